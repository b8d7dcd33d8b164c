"""Rolling friction asks an engine for the capability of the model's own rolling-resistance law:
``rolling-friction`` for ``cdt``, ``rolling-<model>`` for the others, never both."""

import numpy as np
import pytest

from pygran_core import params
from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.engine import Engine
from pygran_core.simulation.models import HertzMindlin
from pygran_core.simulation.specs import parse_simulation


class Epsd2Engine(Engine):
    """An engine whose only rolling-resistance law is epsd2 (it never runs: only opened)."""

    name = "epsd2-only"
    capabilities = frozenset({"hertz-mindlin", "rolling-epsd2"})

    def _advance(self, nsteps: int) -> None:
        raise AssertionError("not run")

    def _extract(self, quantity: str) -> np.ndarray:
        return np.zeros(0)


def open_engine(tmp_path, model, rolling_friction):
    material = dict(params.organic, coefficientRollingFriction=rolling_friction)
    keywords = {
        "box": (0, 1e-2, 0, 1e-2, 0, 1e-2),
        "species": ({"material": material, "radius": 5e-4},),
        "output": str(tmp_path / "out"),
    }
    return Epsd2Engine(parse_simulation(keywords, Epsd2Engine.name, model))


def test_epsd2_runs_without_the_cdt_capability(tmp_path):
    with open_engine(tmp_path, HertzMindlin.configure(rolling="epsd2"), 0.05) as engine:
        assert not engine.closed


def test_cdt_needs_rolling_friction(tmp_path):
    with pytest.raises(UnsupportedFeature, match=r"rolling friction \(capability 'rolling-friction'\)"):
        open_engine(tmp_path, HertzMindlin, 0.05)
    with open_engine(tmp_path, HertzMindlin, 0.0) as engine:  # no rolling friction: nothing needed
        assert not engine.closed
