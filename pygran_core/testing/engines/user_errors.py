"""The engine suite's checks of user mistakes (the table of :mod:`pygran_core.testing.mistakes`):
the same error on every engine, naming what is wrong."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.dem import DEM
from pygran_core.testing import mistakes
from pygran_core.testing.engines.base import EngineSuite


class MistakeChecks(EngineSuite):
    """Mistakes in ``DEM(**params)`` and in calls on a running simulation; settings refused."""

    @pytest.mark.parametrize(
        ("change", "error", "named"), [pytest.param(*r[1:], id=r[0]) for r in mistakes.SETUP]
    )
    def test_setup_mistake(self, tmp_path, change, error, named):
        """A mistake in ``DEM(**params)``: the same error class on every engine, naming the key."""
        with pytest.raises(error) as info:
            DEM(**change(mistakes.valid(tmp_path / "out", self.engine, self.model) | dict(self.options)))
        assert named in str(info.value)

    @pytest.mark.parametrize(
        ("row", "change", "capability", "named"), [pytest.param(*r, id=r[0]) for r in mistakes.UNSUPPORTED]
    )
    def test_setting_honoured_or_refused(self, tmp_path, row, change, capability, named):
        """A setting the engine declares is taken; any other is refused, naming the setting and
        the capability (or, first, the capability its simulation needs besides)."""
        settings = change(mistakes.valid(tmp_path / "out", self.engine, self.model) | dict(self.options))
        needed = mistakes.NEEDS.get(row)
        if needed is not None and not self.supports(needed):
            with pytest.raises(UnsupportedFeature, match=f"capability {needed!r}"):
                DEM(**settings)
            return
        if self.supports(capability):
            DEM(**settings).close()
            return
        with pytest.raises(UnsupportedFeature) as info:
            DEM(**settings)
        assert named in str(info.value) and f"capability {capability!r}" in str(info.value)

    @pytest.fixture(scope="class")
    @classmethod
    def mistaken(cls, tmp_path_factory) -> Iterator[DEM]:
        """The simulation of :func:`mistakes.running` on this engine."""
        suite = cls()
        output = tmp_path_factory.mktemp("mistakes") / "out"
        floor = suite.supports("primitive-walls")
        sim = mistakes.running(output, cls.engine, suite.model, floor, **cls.options)
        yield sim
        sim.close()

    @pytest.mark.parametrize(
        ("call", "error", "named"), [pytest.param(*r[1:], id=r[0]) for r in mistakes.CALL]
    )
    def test_call_mistake(self, mistaken, call, error, named):
        """A mistake in a call on a running simulation: the same error class on every engine,
        naming the key, and refused before it changes anything."""
        sim = mistaken
        before = (sim.step, sim.engine.dt, len(sim.engine.handles), len(sim.extractIds()))
        with pytest.raises(error) as info:
            call(sim)
        assert named in str(info.value)
        assert (sim.step, sim.engine.dt, len(sim.engine.handles), len(sim.extractIds())) == before
