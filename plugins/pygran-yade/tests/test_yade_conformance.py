"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on real YADE."""

from pygran_core.testing.engines import EngineConformance


class TestYadeConformance(EngineConformance):
    engine = "yade"
    options = {"threads": 1}  # test_threads compares with two
    refuses = frozenset({"monitor-wall_force"})
    raw_command = "O.bodies[0].state.vel = (0.5, 0.0, 0.0)"
