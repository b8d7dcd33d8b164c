"""``DEM(pairs=...)``: the material table's pair values, their refusals and the logged table
(the sliding and bounce checks on each engine are in the engine conformance suite)."""

from __future__ import annotations

import numpy as np
import pytest

from pygran_core import params, simulation
from pygran_core.errors import ConfigError, UnsupportedFeature
from pygran_core.simulation.materials import build_table

BOX = (-0.01, 0.01, -0.01, 0.01, -0.01, 0.01)
WALL = np.array([[[-0.009, -0.009, -0.009], [0.009, -0.009, -0.009], [0.0, 0.009, -0.009]]])


def dem(tmp_path, pairs, **keywords):
    species = tuple({"material": params.glass, "radius": 1e-3} for _ in range(2))
    mesh = {"plate": {"triangles": WALL, "material": params.steel}, "bare": {"triangles": WALL}}
    return simulation.DEM(
        **{"engine": "native", "model": simulation.models.HertzMindlin} | keywords,
        box=BOX,
        species=species,
        mesh=mesh,
        pairs=pairs,
        output=str(tmp_path / "out"),
        progress=False,
    )


@pytest.mark.parametrize(
    ("pairs", "named"),
    [
        ({(1, 2): {"coefficientFricton": 0.2}}, "'coefficientFricton'.*coefficientFriction"),
        ({(1, 3): {"coefficientFriction": 0.2}}, "species 3 does not exist"),
        ({(1, "drum"): {"coefficientFriction": 0.2}}, "'drum'.*plate"),
        ({(1, "bare"): {"coefficientFriction": 0.2}}, "mesh 'bare' has no material"),
        ({(1, 2): {"coefficientRestitution": 1.5}}, r"coefficientRestitution=1.5: out of range"),
        ({(1, 2): {"coefficientFriction": -0.1}}, r"coefficientFriction=-0.1: out of range"),
        ({(1, 2): {"coefficientFriction": "0.2"}}, "expected a number"),
        ({(1, 2, 3): {"coefficientFriction": 0.2}}, "must be a pair"),
        ({(1, 2): {"coefficientFriction": 0.2}, (2, 1): {"coefficientFriction": 0.3}}, "given twice"),
        ({(1, 2): {"youngsModulus": 1e9}}, "'youngsModulus'"),
    ],
)
def test_a_wrong_pair_is_refused_by_name(tmp_path, pairs, named):
    with pytest.raises(ConfigError, match=named):
        dem(tmp_path, pairs)


def test_a_pair_the_model_does_not_use_is_refused(tmp_path):
    """Thornton-Ning has no restitution: a pair setting one is refused, not dropped."""
    with pytest.raises(ConfigError, match="coefficientRestitution, which the contact model does not use"):
        dem(tmp_path, {(1, 2): {"coefficientRestitution": 0.5}}, model=simulation.models.ThorntonNing)


def test_pairs_replace_the_mixing_rules_and_the_table_is_logged(tmp_path):
    """Pair (1, 'plate') given, in either order; the other pairs mixed (friction the smaller,
    restitution the geometric mean); the table in pygran.log, given pairs starred."""
    with dem(tmp_path, {("plate", 1): {"coefficientFriction": 0.2, "coefficientRestitution": 0.4}}) as sim:
        table = sim.engine.material_table
    glass, steel = params.glass, params.steel
    assert table.names == ("species 1", "species 2", "mesh plate")
    assert dict(table.mesh_types) == {"plate": 2}
    friction, restitution = table.pairs["coefficientFriction"], table.pairs["coefficientRestitution"]
    assert friction[0, 2] == friction[2, 0] == 0.2 and restitution[2, 0] == 0.4
    assert friction[1, 2] == min(glass["coefficientFriction"], steel["coefficientFriction"])
    assert restitution[1, 2] == pytest.approx(
        np.sqrt(glass["coefficientRestitution"] * steel["coefficientRestitution"]), rel=1e-15
    )
    log = (tmp_path / "out" / "pygran.log").read_text()
    assert "species 1 - mesh plate*" in log and "species 2 - mesh plate " in log


def test_defaults_table_and_required_keys():
    """A material with only a model's required keys: friction, rolling friction and cohesion 0;
    a missing required key is a ConfigError naming it and the type."""
    bare = {"youngsModulus": 1e7, "poissonsRatio": 0.3, "coefficientRestitution": 0.5}
    table = build_table([bare], [], (), simulation.models.HertzMindlin.required)
    for key in ("coefficientFriction", "coefficientRollingFriction", "cohesionEnergyDensity"):
        assert table.pairs[key].tolist() == [[0.0]]
    with pytest.raises(ConfigError, match="'coefficientRestitution' in every material: species 2"):
        build_table([bare, {"youngsModulus": 1e7, "poissonsRatio": 0.3}], [], (), ("coefficientRestitution",))


@pytest.mark.parametrize("engine", ["native", "liggghts", "yade"])
def test_a_mesh_pair_is_honoured(tmp_path, engine):
    """A sphere sliding on a mesh plate: friction 0.5 for the sphere's material and 0 for the
    plate's mix to 0; pairs={(1, 'plate'): 0.2} makes it decelerate at 0.2 g."""
    from pygran_core import registry
    from pygran_core.testing.solvers import require_solver

    locate = registry.get_engine(engine).locate_solver
    if locate is not None:
        require_solver(locate)
    corners = np.array(
        [[-0.009, -0.009, 0.0], [0.009, -0.009, 0.0], [0.009, 0.009, 0.0], [-0.009, 0.009, 0.0]]
    )
    plate = np.array([corners[[0, 1, 2]], corners[[0, 2, 3]]])
    # well damped (restitution 0.3): the sphere rests on the plate after the first millisecond
    material = dict(params.glass, youngsModulus=1e7, coefficientFriction=0.5, coefficientRestitution=0.3)
    material.pop("cohesionEnergyDensity", None)  # YADE has no cohesion
    with simulation.DEM(
        engine=engine,
        model=simulation.models.HertzMindlin,
        box=BOX,
        species=({"material": material, "radius": 1e-3},),
        mesh={"plate": {"triangles": plate, "material": dict(material, coefficientFriction=0.0)}},
        pairs={(1, "plate"): {"coefficientFriction": 0.2}},
        gravity=(9.81, 0, 0, -1),
        dt=2e-6,
        output=str(tmp_path),
        progress=False,
        traj={"pfile": None},
    ) as sim:
        sim.createParticles(1, "single", 0.0, -0.005, 1e-3, vel=(0.0, 0.1, 0.0))
        sim.run(1000)
        early = sim.time, sim.extractVelocities()[0, 1]
        sim.run(2500)
        deceleration = (early[1] - sim.extractVelocities()[0, 1]) / (sim.time - early[0])
    assert deceleration == pytest.approx(0.2 * 9.81, rel=0.01)


def test_an_engine_without_pair_tables_refuses_them(tmp_path, with_plugins):
    """A plugin engine that does not read the material table (the toy plugin's) cannot honour
    pairs=: refused before it starts, naming the engines that can."""
    with_plugins("pygran-toy")
    species = ({"material": params.glass, "radius": 1e-3},)
    with pytest.raises(UnsupportedFeature, match=r"pairs=.*'pair-tables'.*liggghts, native, yade"):
        simulation.DEM(
            engine="toy",
            box=BOX,
            species=species,
            pairs={(1, 1): {"coefficientFriction": 0.2}},
            output=str(tmp_path / "toy"),
        )
