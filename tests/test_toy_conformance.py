"""The engine conformance suite (:mod:`pygran_core.testing.engines`) on the toy engine of the
third-party test plugin ``tests/plugins/pygran-toy``, installed with pip for the class."""

import pytest

from pygran_core import registry
from pygran_core.testing.engines import EngineConformance


class TestToyConformance(EngineConformance):
    engine = "toy"
    refuses = frozenset(
        {
            "insert",
            "create-lattice",
            "create-random",
            "set",
            "set-radius",
            "viscous",
            "monitor-ke_rot",
            "monitor-contacts",
            "monitor-wall_force",
        }
    )

    @pytest.fixture(scope="class")
    @classmethod
    def engine_plugin(cls, plugin_target):
        with pytest.MonkeyPatch.context() as patch:
            patch.syspath_prepend(str(plugin_target("pygran-toy")))
            registry.refresh()
            yield
        registry.refresh()
