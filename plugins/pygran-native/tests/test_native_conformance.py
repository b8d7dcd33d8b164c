"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on the native engine."""

from pygran_core.testing.engines import EngineConformance


class TestNativeConformance(EngineConformance):
    engine = "native"
    options = {"threads": 1}  # test_threads compares with two
    refuses = frozenset({"monitor-wall_force"})
