"""PyGran 1.x simulation scripts, written the way its users wrote them, run unchanged.

A params dict with the script's own keys, float step counts, materials changed in place,
meshes with args dicts, monitor the old way, species inserted one after the other; each
script runs on native and on LIGGGHTS and is checked against the physics.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from PyGran import analysis, simulation
from pygran_core import registry
from pygran_core.errors import UnsupportedFeature

MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"
ENGINES = ["native", "liggghts"]


def require(engine):
    if engine == "liggghts":
        from pygran_liggghts.library import find_library

        from pygran_core.testing.solvers import require_solver

        require_solver(find_library)


def flow(engine, output):
    """The original flow demo, smaller: fill a hopper above a turning impeller, then open it."""
    from PyGran.params import glass, organic

    organic["coefficientRestitution"] = 0.5  # settles sooner
    params = {
        "engine": engine,
        "output": output,
        "boundary": ("f", "f", "f"),
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, -2e-3, 4e-3),
        "species": ({"material": organic, "radius": ("constant", 5e-5)},),
        "traj": {"freq": 1e4, "pfile": "traj.dump"},
        "dt": 1e-6,
        "gravity": (9.81, 0, 0, -1),
        "mesh": {
            "hopper": {
                "file": str(MESHES / "silo.stl"),
                "mtype": "mesh/surface",
                "material": glass,
                "args": {"scale": 1e-3},
            },
            # moved by 1 (mm) before it is scaled: 1.5 mm up, inside the hopper
            "impeller": {
                "file": str(MESHES / "valve.stl"),
                "mtype": "mesh/surface",
                "material": glass,
                "args": {"move": (0, 0, 1), "scale": 1e-3},
            },
        },
        "stages": {"insertion": 2e4, "run": 1e4, "discharge": 1.5e4},
    }
    sim = simulation.DEM(**params)
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=-1.5e-3)  # collects what leaves
    stopper = sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    ke = sim.monitor(
        var="ke", species="all", name="ensemble_ke", file="ke.dat", nevery=100, nfreq=1000, nrepeat=10
    )
    insert = sim.insert(
        species=1,
        region=("block", -3e-4, 3e-4, -3e-4, 3e-4, 2e-3, 3e-3),
        mech="volumefraction_region",
        value=1,
        freq=1e4,
    )
    sim.run(params["stages"]["insertion"], params["dt"])
    sim.remove(insert)
    filled = sim.extractCoords()
    turn = sim.moveMesh(name="impeller", rotate=("origin", 0, 0, 0), axis=(0, 0, 1), period=5e-2)
    sim.run(params["stages"]["run"], params["dt"])
    sim.remove(turn)
    settled = sim.extractCoords()
    sim.remove(stopper)
    sim.run(params["stages"]["discharge"], params["dt"])
    final = sim.extractCoords()
    sim.close()
    return sim, ke, filled, settled, final, organic


@pytest.mark.parametrize("engine", ENGINES)
def test_hopper_with_an_impeller_discharges_once_opened(engine, tmp_path):
    require(engine)
    sim, ke, filled, settled, final, organic = flow(engine, str(tmp_path / "out"))
    impeller = sim.spec.meshes[1].triangles()
    assert impeller[..., 2].min() == pytest.approx(1.5e-3) and impeller[..., 2].max() == pytest.approx(1.5e-3)
    region_volume = 6e-4 * 6e-4 * 1e-3
    sphere = 4 / 3 * math.pi * 5e-5**3
    assert 0.2 * region_volume / sphere < len(filled) < 2 * 0.64 * region_volume / sphere
    box = np.array(sim.spec.domain.box)
    for positions in (filled, settled, final):
        assert np.all((positions >= box[:, 0]) & (positions <= box[:, 1]))
    assert len(settled) == len(filled) and settled[:, 2].min() > 0  # held by the stopper
    assert len(final) == len(filled)  # nothing lost: the floor below collects what flows out
    out = np.count_nonzero(final[:, 2] < 0)
    assert out > 0.2 * len(filled), f"only {out} of {len(filled)} left the hopper"
    values = ke.values
    assert values["step"][0] == 1000 and np.all(np.diff(values["ke"][:5]) > 0)  # falling
    if engine == "native":
        log = (tmp_path / "out" / "pygran.log").read_text()
        # two insertions, at the steps 0 and 10000, none at the end of the run (20000)
        made = [line.split("insert at step ")[1] for line in log.splitlines() if "insert at step " in line]
        assert [entry.split(":")[0] for entry in made] == ["0", "10000"]
        # free fall up to the first average: the sum of m (g t)^2 / 2
        first = int(made[0].split()[1])
        mass = organic["density"] * sphere
        expected = first * np.mean(0.5 * mass * (9.81 * np.arange(100, 1001, 100) * 1e-6) ** 2)
        assert values["ke"][0] == pytest.approx(expected, rel=1e-6)


def mixture(engine, output, scale):
    """The original mixture demo (its lengths times ``scale``): two species inserted one
    after the other."""
    from PyGran.params import glass, stearicAcid

    params = {
        "engine": engine,
        "boundary": ("p", "p", "f"),
        "box": tuple(scale * x for x in (-0.00025, 0.00025, -0.00025, 0.00025, 0, 0.0005)),
        "species": (
            {"material": stearicAcid, "radius": ("constant", scale * 25.00e-6)},
            {"material": glass, "radius": ("constant", scale * 25.00e-6)},
        ),
        "traj": {"freq": 100000, "pfile": "traj.dump"},
        "output": output,
        "dt": 2e-9,
        "gravity": (9.81, 0, 0, -1),
        "stages": {"insertion": 1e3, "run": 1e3, "relax": 0e5},
    }
    sim = simulation.DEM(**params)
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    counts = []
    for species in [1, 2]:
        insert = sim.insert(species, value=100)
        sim.run(1, params["dt"])
        sim.remove(insert)
        counts.append(len(sim.extractIds()))
    sim.run(params["stages"]["insertion"], params["dt"])
    return sim, counts


# LIGGGHTS refuses the demo's 0.5 mm box as an insertion region (below its default region
# volume_limit of 1e-10 m^3): it runs 4 times larger there
@pytest.mark.parametrize(("engine", "scale"), [("native", 1), ("liggghts", 4)])
def test_two_species_inserted_one_after_the_other(engine, scale, tmp_path):
    require(engine)
    sim, counts = mixture(engine, str(tmp_path / "out"), scale)
    with sim:
        assert counts == [100, 200]
        assert np.bincount(sim.engine.extract("type").astype(int)).tolist() == [0, 100, 100]
        z = sim.extractCoords()[:, 2]
        assert np.all((z > 0) & (z < scale * 5e-4))


@pytest.mark.parametrize("engine", ENGINES)
def test_a_vibrating_plate_is_honoured_or_refused(engine, tmp_path):
    """The mixture demo's tapping: viblin along z, amplitude 12.5 um at 40 Hz."""
    require(engine)
    from PyGran.params import stearicAcid

    params = {
        "engine": engine,
        "box": (-5e-4, 5e-4, -5e-4, 5e-4, -5e-4, 5e-4),
        "species": ({"material": stearicAcid, "radius": 25e-6},),
        "mesh": {
            "wall": {"file": str(MESHES / "square.stl"), "args": {"scale": 2.5e-4, "move": (0, 0, -8e-4)}}
        },
        "traj": {"pfile": None, "mfile": "wall*.vtk", "freq": 6250},
        "dt": 1e-6,
        "output": str(tmp_path / "out"),
    }
    period = 1.0 / 40
    tap = {"viblin": ("axis", 0, 0, 1), "order": 1, "amplitude": 12.5e-6, "phase": 0, "period": period}
    with simulation.DEM(**params) as sim:
        if "mesh-vibration" not in registry.get_engine(engine).capabilities:
            with pytest.raises(
                UnsupportedFeature, match="viblin mesh motion \\(capability 'mesh-vibration'\\)"
            ):
                sim.moveMesh(name="wall", **tap)
            return
        sim.moveMesh(name="wall", **tap)
        sim.run(period / params["dt"])
    system = analysis.System(Mesh=str(tmp_path / "out" / "wall*.vtk"))
    z = [float(np.mean(system.Mesh.points[:, 2])) for _ in system.frames()]
    # LIGGGHTS' viblin: z(t) - z(0) = A (cos(w t + phase) - cos(phase)) at t = 0, T/4, T/2, 3T/4, T
    base = 3 * 2.5e-4 - 8e-4  # square.stl lies at z = 3: scaled, then moved
    expected = [base + 12.5e-6 * (math.cos(2 * math.pi * k / 4) - 1) for k in range(5)]
    np.testing.assert_allclose(z, expected, atol=1e-8)


@pytest.mark.parametrize("engine", ENGINES)
def test_insertions_by_rate_happen_at_the_same_steps(engine, tmp_path):
    """4 particles each time, every 100 steps: 10 in a run of 1000 steps (none at its last
    step), then 5 in a run of 500 that starts with the one due at step 1000."""
    require(engine)
    from PyGran.params import stearicAcid

    stearicAcid["cohesionEnergyDensity"] = 0.0
    params = {
        "engine": engine,
        "box": (-2e-2, 2e-2, -2e-2, 2e-2, -2e-2, 2e-2),
        "species": ({"material": stearicAcid, "radius": 1e-3},),
        "dt": 5e-6,
        "output": str(tmp_path / "out"),
        "traj": {"pfile": None},
    }
    with simulation.DEM(**params) as sim:
        region = ("block", -1.8e-2, 1.8e-2, -1.8e-2, 1.8e-2, -1.8e-2, 1.8e-2)
        sim.insert(1, insert="by_rate", rate=8000, freq=100, region=region)
        sim.run(1e3)
        first = len(sim.extractIds())
        sim.run(5e2)
        second = len(sim.extractIds())
    assert (first, second) == (40, 60)


@pytest.mark.parametrize("engine", ENGINES)
def test_meshes_are_walls_from_the_start_unless_not_imported(engine, tmp_path):
    """A plate at z = 1 mm holds a sphere dropped on it; a plate with 'import': False does
    not, until setupWall makes it a wall; remove('plate') takes the wall away again."""
    require(engine)
    from PyGran.params import organic

    organic["youngsModulus"] = 1e6  # soft: a longer time step
    organic["coefficientRestitution"] = 0.3  # settles sooner
    organic["cohesionEnergyDensity"] = 0.0

    def drop(name, imported):
        plate = {
            "file": str(MESHES / "square.stl"),
            "material": organic,
            "args": {"move": (0, 0, -2), "scale": 1e-3},
        }
        if not imported:
            plate["import"] = False
        params = {
            "engine": engine,
            "model": simulation.models.HertzMindlin,
            "box": (-2e-3, 2e-3, -2e-3, 2e-3, -1e-3, 3e-3),
            "species": ({"material": organic, "radius": 1e-4},),
            "mesh": {"plate": plate},
            "gravity": (9.81, 0, 0, -1),
            "dt": 2e-6,
            "output": str(tmp_path / name),
            "traj": {"pfile": None},
        }
        sim = simulation.DEM(**params)
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=-5e-4)
        sim.createParticles(1, "single", 0.0, 0.0, 1.5e-3)
        return sim

    on_plate, on_floor = 1e-3 + 1e-4, -5e-4 + 1e-4
    with drop("imported", True) as sim:
        sim.run(1.5e4)
        assert sim.extractCoords()[0, 2] == pytest.approx(on_plate, abs=1e-6)
        sim.remove("plate")
        sim.run(2.5e4)
        assert sim.extractCoords()[0, 2] == pytest.approx(on_floor, abs=1e-6)
    with drop("not-imported", False) as sim:
        sim.run(2.5e4)
        assert sim.extractCoords()[0, 2] == pytest.approx(on_floor, abs=1e-6)  # through the plate
        sim.setupWall(wtype="mesh", mesh="plate")
        sim.createParticles(1, "single", 0.0, 0.0, 1.5e-3)
        sim.run(1.5e4)
        assert sim.extractCoords()[1, 2] == pytest.approx(on_plate, abs=1e-6)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_mesh_turns_about_the_origin_given(engine, tmp_path):
    """moveMesh(name, rotate=('origin', x, y, z), axis=..., period=...): a quarter turn about
    a vertical axis 1 mm off the plate's centre."""
    require(engine)
    from PyGran.params import organic

    params = {
        "engine": engine,
        "box": (-4e-3, 4e-3, -4e-3, 4e-3, -1e-3, 1e-3),
        "species": ({"material": organic, "radius": 1e-4},),
        "mesh": {"plate": {"file": str(MESHES / "square.stl"), "args": {"move": (0, 0, -3), "scale": 1e-3}}},
        "traj": {"pfile": None, "mfile": "plate*.vtk", "freq": 1e3},
        "dt": 1e-5,
        "output": str(tmp_path / "out"),
    }
    with simulation.DEM(**params) as sim:
        sim.moveMesh("plate", rotate=("origin", 1e-3, 0, 0), axis=(0, 0, 1), period=4e-2)
        sim.run(1e3)
    system = analysis.System(Mesh=str(tmp_path / "out" / "plate*.vtk"))
    frames = [np.array(system.Mesh.points) for _ in system.frames()]
    system.close()
    start, turned = frames[0], frames[-1]
    quarter = (start - [1e-3, 0, 0]) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + [1e-3, 0, 0]
    np.testing.assert_allclose(turned, quarter, atol=1e-8)
    assert np.abs(turned[:, 0].mean() - start[:, 0].mean()) > 5e-4  # not about the plate's centre
