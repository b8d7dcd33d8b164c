"""Rolling resistance on LIGGGHTS: the contact model's ``rolling`` (cdt by default, as the
original PyGran; epsd, epsd2) becomes ``rolling_friction <name>``.

200 spheres (radius 0.1 mm) poured through a funnel (silo.stl at twice its size, outlet 1.2 mm
across) onto a floor 1 mm below its outlet, for 40 ms. Without rolling resistance the spheres
roll away from the heap; with it (mu_r = 0.3) they stay: the heap's angle, atan(height /
radius holding 90 % of the spheres), is at least 1.5 times larger.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import simulation
from pygran_core.errors import UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin
from pygran_core.testing.solvers import require_solver
from pygran_core.testing.validation import SOFT

FUNNEL = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "silo.stl"
RADIUS, FLOOR = 1e-4, -1e-3
#: The suite's soft material, less incompressible, with rolling damping.
MATERIAL = dict(SOFT, poissonsRatio=0.3, coefficientRollingViscousDamping=0.3)


def pile_angle(output: Path, model: type[HertzMindlin], rolling_friction: float) -> float:
    """The angle (degrees) of the heap poured with this model and rolling friction coefficient."""
    material = dict(MATERIAL, coefficientRollingFriction=rolling_friction)
    with simulation.DEM(
        engine="liggghts",
        model=model,
        box=(-4e-3, 4e-3, -4e-3, 4e-3, FLOOR, 6.2e-3),
        gravity=(9.81, 0, 0, -1),
        dt=1e-6,
        output=str(output),
        species=({"material": material, "radius": RADIUS},),
        mesh={"funnel": {"file": str(FUNNEL), "material": material, "args": ("scale 2e-3",)}},
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.setupWall(wtype="mesh", mesh="funnel")
        sim.setupWall(plane="zplane", peq=FLOOR)
        sim.insert(species=1, value=200, region=("cylinder", "z", 0, 0, 7e-4, 1e-3, 4e-3), vel=(0, 0, -0.1))
        sim.run(40_000)
        x = sim.extractCoords()
    assert len(x) == 200 and np.all(x[:, 2] < 0), "every sphere has left the funnel"
    height = x[:, 2].max() + RADIUS - FLOOR
    return math.degrees(math.atan(height / np.quantile(np.hypot(x[:, 0], x[:, 1]), 0.9)))


class Epsd(HertzMindlin):
    rolling = "epsd"


class Epsd2(HertzMindlin):
    rolling = "epsd2"


@pytest.fixture(scope="module")
def free_rolling(tmp_path_factory) -> float:
    require_solver(find_library)
    return pile_angle(tmp_path_factory.mktemp("free"), HertzMindlin, 0.0)


@pytest.mark.parametrize("model", [HertzMindlin, Epsd, Epsd2], ids=["cdt", "epsd", "epsd2"])
def test_rolling_resistance_steepens_a_poured_heap(tmp_path, free_rolling, model):
    angle = pile_angle(tmp_path, model, 0.3)
    assert angle > 1.5 * free_rolling, (angle, free_rolling)
    script = (tmp_path / "in.pygran").read_text()
    assert f"pair_style gran model hertz tangential history rolling_friction {model.rolling}\n" in script
    assert ("coefficientRollingViscousDamping" in script) == (model.rolling == "epsd")


class Epsd3(HertzMindlin):
    rolling = "epsd3"


class Stiffer(HertzMindlin):
    def normal_force(self, overlap, overlap_rate, max_overlap=None):
        return 2 * super().normal_force(overlap, overlap_rate, max_overlap)


@pytest.mark.parametrize(
    ("model", "reason"),
    [(Epsd3, "epsd3 needs coeffRollingStiffness"), (Stiffer, "Stiffer declares no kernel")],
)
def test_what_liggghts_cannot_run_is_refused(tmp_path, model, reason):
    material = dict(MATERIAL, coefficientRollingFriction=0.3)
    with pytest.raises(UnsupportedFeature, match=reason):
        simulation.DEM(
            engine="liggghts",
            model=model,
            box=(0, 1e-3, 0, 1e-3, 0, 1e-3),
            output=str(tmp_path),
            species=({"material": material, "radius": RADIUS},),
            progress=False,
        )
