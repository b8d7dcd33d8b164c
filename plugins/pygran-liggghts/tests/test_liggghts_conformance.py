"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on real LIGGGHTS."""

from pygran_core.testing.engines import EngineConformance


class TestLiggghtsConformance(EngineConformance):
    engine = "liggghts"
    refuses = frozenset({"monitor-contacts", "monitor-wall_force", "mesh-vibration"})
    raw_command = "set atom 1 vx 0.5"
