"""ThorntonNing on LIGGGHTS through PyGran's compiled add-on (``gran model thornton_ning_pygran``):
declared when the add-on loads and refused with the reason when it does not; Thornton's (1997)
restitution, the JKR pull-off force and native's force at every step; under MPI and across a
LIGGGHTS restart written in the middle of the impacts."""

import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from pygran_liggghts import library
from pygran_liggghts.library import ADDON_MODEL, find_library, probe_addon
from pygran_liggghts.session import mpirun_prefix

from pygran_core import registry, simulation
from pygran_core.errors import EngineError, UnsupportedFeature
from pygran_core.simulation.models import ThorntonNing
from pygran_core.testing import validation
from pygran_core.testing.solvers import require_solver

R = validation.RADIUS
SPEED = validation.IMPACT_SPEED
#: Thornton's (1997) restitution table: yield-to-impact speed ratio -> e (non-adhesive).
THORNTON_TABLE = {1.0: 1.0, 0.5: 0.931, 0.2: 0.773, 0.1: 0.659, 0.05: 0.557, 0.01: 0.374}


def locate_addon() -> str:
    """The add-on's model name, or the EngineError saying why it is unavailable."""
    addon = probe_addon()
    if not addon.loaded:
        raise EngineError(addon.reason)
    return ADDON_MODEL


@pytest.fixture(autouse=True)
def addon():
    """LIGGGHTS and the add-on: a failure with CI=true, else a skip saying how to build it."""
    require_solver(find_library)
    require_solver(locate_addon)


def test_the_engine_declares_thornton_ning():
    assert "thornton-ning" in registry.get_engine("liggghts").capabilities


def test_pygran_validate_thornton_ning_on_liggghts(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pygran_core.cli",
            "validate",
            "--engine",
            "liggghts",
            "--check",
            "thornton-ning",
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    table = [re.split(r"\s{2,}", line) for line in done.stdout.splitlines()]
    # check, expected, obtained (with units), tolerance, result, notes
    rows = {
        row[0]: (float(row[2].split()[0]), row[4])
        for row in table
        if len(row) >= 5 and row[4] in ("pass", "FAIL")
    }
    for ratio, restitution in THORNTON_TABLE.items():
        obtained, status = rows[f"Thornton-Ning e at V_y/V = {ratio:g}"]
        assert status == "pass" and obtained == pytest.approx(restitution, rel=0.01), (ratio, obtained)
    pull_off, status = rows["JKR pull-off force"]
    assert status == "pass" and pull_off == pytest.approx(3 * np.pi * 0.05 * R, rel=0.01)
    difference, status = rows["Thornton-Ning trace vs native"]
    assert status == "pass" and difference < 1e-6


def test_the_adhesive_neck_lasts_to_the_reference_separation_overlap(tmp_path):
    """An elastic adhesive sphere leaves a wall through a neck at negative overlap, pulled until
    the overlap passes the reference model's separation overlap, step for step as on native."""
    material = validation.ELASTIC_ADHESIVE
    trace = validation.impact_trace("liggghts", tmp_path / "liggghts", ThorntonNing, material)
    native = validation.impact_trace("native", tmp_path / "native", ThorntonNing, material)
    overlap, force = trace.T
    touching = np.nonzero(force)[0]
    neck = touching[overlap[touching] < 0]
    assert neck.size > 5 and force[neck].max() < 0  # pulled apart while not overlapping
    model = ThorntonNing(material=dict(material, radius=R))
    separation = model._separation_overlap(overlap.max())
    assert separation < 0
    assert overlap[touching[-1]] > separation > overlap[touching[-1] + 1]
    assert -force.min() == pytest.approx(model.pull_off_force, rel=0.01)
    assert np.abs(trace - native).max(axis=0) / np.abs(native).max(axis=0) == pytest.approx([0, 0], abs=1e-6)


def test_without_the_addon_thornton_ning_is_refused_with_the_reason(tmp_path):
    script = textwrap.dedent(
        f"""
        from pygran_core import simulation
        from pygran_core.errors import UnsupportedFeature
        from pygran_core.testing.validation import IMPACT_MATERIALS
        from pygran_core.simulation.models import ThorntonNing

        try:
            simulation.DEM(engine="liggghts", model=ThorntonNing, output={str(tmp_path / "out")!r},
                           box=(-0.01, 0.01, -0.01, 0.01, -0.01, 0.01),
                           species=({{"material": IMPACT_MATERIALS[ThorntonNing], "radius": 1e-3}},))
        except UnsupportedFeature as exc:
            print("refused:", exc)
        """
    )
    env = {"PYGRAN_LIGGGHTS_LIB": str(tmp_path / "missing.so"), "PATH": "/usr/bin:/bin"}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0, done.stderr
    reason = "no LIGGGHTS shared library ($PYGRAN_LIGGGHTS_LIB or the dynamic loader)"
    assert "refused: The liggghts engine does not support the ThorntonNing contact model" in done.stdout
    assert "capability 'thornton-ning'" in done.stdout and reason in done.stdout
    assert f"ThorntonNing unavailable on LIGGGHTS: {reason}" in done.stderr  # logged on loading
    assert reason in (tmp_path / "out" / "pygran.log").read_text()


# -- MPI and restart ----------------------------------------------------------------------------------

#: Two plastic adhesive spheres meeting head-on at x = 0, and an elastic adhesive one hitting
#: the floor: species 1 and 2 (the floor has species 2's material).
SPECIES = (
    {"material": validation.ADHESIVE, "radius": R},
    {"material": validation.ELASTIC_ADHESIVE, "radius": R},
)
DT = (
    ThorntonNing(material=dict(validation.ADHESIVE, radius=R)).contactTime(SPEED)
    / validation.STEPS_PER_CONTACT
)
#: The elastic sphere is in its neck (negative overlap, pulled) at this step.
NECK_STEP = 410


def impacts(output: Path, engine: str = "liggghts", **options) -> np.ndarray:
    """Velocities by id after 3 x NECK_STEP steps (a box long in x: two ranks split it at x = 0)."""
    start = R + 0.5 * SPEED * DT
    with simulation.DEM(
        engine=engine,
        model=ThorntonNing,
        box=(-8 * R, 8 * R, -2 * R, 2 * R, -R, 4 * R),
        dt=DT,
        output=str(output),
        species=SPECIES,
        traj={"pfile": None},
        progress=False,
        **options,
    ) as sim:
        sim.setupWall(species=2, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", -start, 0.0, 2 * R, vel=(SPEED, 0.0, 0.0))
        sim.createParticles(1, "single", start, 0.0, 2 * R, vel=(-SPEED, 0.0, 0.0))
        sim.createParticles(2, "single", 5 * R, 0.0, start, vel=(0.0, 0.0, -SPEED))
        sim.run(3 * NECK_STEP)
        return sim.extractVelocities()


@pytest.fixture(scope="module")
def on_native(tmp_path_factory):
    return impacts(tmp_path_factory.mktemp("native"), engine="native")


def test_two_ranks_give_native_impacts(tmp_path, on_native):
    velocities = impacts(tmp_path, nprocs=2)
    assert "2 by 1 by 1 MPI processor grid" in (tmp_path / "liggghts.log").read_text()
    np.testing.assert_allclose(velocities, on_native, rtol=1e-9, atol=1e-12 * SPEED)
    assert velocities[0, 0] < 0 < velocities[1, 0] and velocities[2, 2] > 0  # all three rebounded


def test_under_mpirun_each_rank_loads_the_addon(tmp_path, on_native):
    """A script started with ``mpirun -np 2`` runs LIGGGHTS in both ranks, each with the add-on."""
    script = tmp_path / "impacts.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import sys
            from pathlib import Path
            from mpi4py import MPI
            sys.path.insert(0, {str(Path(__file__).parent)!r})
            from test_liggghts_thornton_ning import impacts

            velocities = impacts(Path({str(tmp_path / "out")!r}))
            if MPI.COMM_WORLD.rank == 0:
                print(repr(velocities.tolist()))
            """
        )
    )
    done = subprocess.run(
        [*mpirun_prefix(2), sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 by 1 by 1 MPI processor grid" in (tmp_path / "out" / "liggghts.log").read_text()
    velocities = np.array(eval(done.stdout.strip().splitlines()[-1]))
    np.testing.assert_allclose(velocities, on_native, rtol=1e-9, atol=1e-12 * SPEED)


def test_a_restart_in_the_neck_continues_the_impacts(tmp_path, on_native):
    straight = impacts(tmp_path / "straight", restart=(NECK_STEP, "restart", "restart.*.h5"))
    np.testing.assert_allclose(straight, on_native, rtol=1e-9, atol=1e-12 * SPEED)
    resumed = tmp_path / "resumed"
    shutil.copytree(tmp_path / "straight", resumed)
    again = impacts(resumed, restart=(NECK_STEP, "restart", "restart.*.h5", True, f"restart.{NECK_STEP}.h5"))
    assert "resum" in (resumed / "pygran.log").read_text()
    # the contact histories came back with LIGGGHTS' restart file: without them the neck
    # would be gone and the plastic contact would reload as a virgin one
    np.testing.assert_allclose(again, straight, rtol=1e-9, atol=1e-12 * SPEED)


# -- friction ------------------------------------------------------------------------------------------


def oblique(output: Path, engine: str, material, rolling: str | None = None) -> np.ndarray:
    """A sphere hitting the floor at 60 degrees and two spheres meeting off-centre, with
    friction: velocities and angular velocities by id after the contacts have ended."""
    start = R + 0.5 * SPEED * DT
    model = ThorntonNing if rolling is None else type("Rolling", (ThorntonNing,), {"rolling": rolling})
    with simulation.DEM(
        engine=engine,
        model=model,
        box=(-8 * R, 8 * R, -2 * R, 2 * R, -R, 4 * R),
        dt=DT,
        output=str(output),
        species=({"material": material, "radius": R},),
        traj={"pfile": None},
        progress=False,
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, start, vel=(0.5 * SPEED, 0.0, -SPEED))
        sim.createParticles(1, "single", -4 * R, 0.0, 2 * R, vel=(SPEED, 0.0, 0.0))
        sim.createParticles(1, "single", -2 * R + 0.5 * SPEED * DT, 0.3 * R, 2 * R, vel=(-SPEED, 0.0, 0.0))
        sim.run(3 * NECK_STEP)
        return np.hstack([sim.extractVelocities(), sim.extractOmegas()])


@pytest.mark.parametrize(
    "material",
    [validation.IMPACT_MATERIALS[ThorntonNing], validation.ADHESIVE, validation.ELASTIC_ADHESIVE],
    ids=["plastic", "plastic-adhesive", "elastic-adhesive-neck"],
)
def test_oblique_impacts_spin_as_on_native(tmp_path, material):
    """Friction while loading, unloading, in an adhesive neck apart and after a plastic contact
    has parted while the bodies still overlap: the same spins and velocities as native's."""
    on_liggghts = oblique(tmp_path / "liggghts", "liggghts", material)
    on_native = oblique(tmp_path / "native", "native", material)
    assert np.abs(on_native[:, 3:]).max() > 1.0  # the contacts spun the spheres (rad/s)
    np.testing.assert_allclose(on_liggghts, on_native, rtol=1e-9, atol=1e-9 * np.abs(on_native).max())


def test_rolling_friction_with_adhesion_is_refused(tmp_path):
    material = dict(validation.ADHESIVE, coefficientRollingFriction=0.3)
    with pytest.raises(UnsupportedFeature, match="adhesion .* and rolling friction together"):
        oblique(tmp_path, "liggghts", material)
    dry = dict(validation.IMPACT_MATERIALS[ThorntonNing], coefficientRollingFriction=0.3)
    on_liggghts = oblique(tmp_path / "liggghts", "liggghts", dry, rolling="cdt")
    on_native = oblique(tmp_path / "native", "native", dry, rolling="cdt")
    np.testing.assert_allclose(on_liggghts, on_native, rtol=1e-9, atol=1e-9 * np.abs(on_native).max())


# -- mesh walls -----------------------------------------------------------------------------------------

#: A point inside one of the triangles of ``square.stl`` (a plate at z = 3 mm), far from its edges.
ON_PLATE = (0.65e-3, -0.31e-3)


def on_plate(
    output: Path, engine: str, material, plate: Path | None, velocity: tuple[float, float, float]
) -> np.ndarray:
    """A sphere hitting the mesh ``plate`` (``square.stl``), or without one the plane z = 3 mm,
    at ``velocity``: its velocity and angular velocity after 3 x NECK_STEP steps."""
    mesh = {"plate": {"file": str(plate), "args": ("scale 1e-3",), "material": material}}
    with simulation.DEM(
        engine=engine,
        model=ThorntonNing,
        box=(-3 * R, 3 * R, -3 * R, 3 * R, 0.0, 6 * R),
        dt=DT,
        output=str(output),
        species=({"material": material, "radius": R},),
        mesh=mesh if plate is not None else None,
        traj={"pfile": None},
        progress=False,
    ) as sim:
        if plate is not None:
            sim.setupWall(wtype="mesh", mesh="plate", species=1)
        else:
            sim.setupWall(species=1, plane="zplane", peq=3e-3)
        sim.createParticles(1, "single", *ON_PLATE, 3e-3 + R + 0.5 * SPEED * DT, vel=velocity)
        sim.run(3 * NECK_STEP)
        return np.hstack([sim.extractVelocities(), sim.extractOmegas()])[0]


def test_mesh_walls_have_the_same_law(tmp_path, data_dir):
    """An adhesive neck on a triangle mesh pulls and rubs as on native; a plastic impact on it
    rebounds as on a plane wall, with Thornton's restitution."""
    plate = data_dir / "meshes" / "square.stl"
    oblique_velocity = (0.3 * SPEED, 0.0, -SPEED)
    material = validation.ELASTIC_ADHESIVE
    on_mesh = on_plate(tmp_path / "neck", "liggghts", material, plate, oblique_velocity)
    on_native = on_plate(tmp_path / "neck-native", "native", material, plate, oblique_velocity)
    assert abs(on_native[4]) > 1.0  # spun by friction (rad/s)
    np.testing.assert_allclose(on_mesh, on_native, rtol=1e-9, atol=1e-9 * np.abs(on_native).max())
    dry = validation.IMPACT_MATERIALS[ThorntonNing]
    head_on = (0.0, 0.0, -SPEED)
    mesh = on_plate(tmp_path / "plastic", "liggghts", dry, plate, head_on)
    plane = on_plate(tmp_path / "plastic-plane", "liggghts", dry, None, head_on)
    np.testing.assert_allclose(mesh, plane, rtol=1e-9, atol=1e-12 * SPEED)
    assert mesh[2] / SPEED == pytest.approx(validation.thornton_restitution(dry, R, SPEED), rel=0.01)


def test_a_neck_beyond_the_contact_distance_stops_the_run_saying_so(tmp_path):
    """Gamma = 50 J/m^2 would hold a 1 mm sphere to a wall until 16 % of its radius apart, beyond
    the 5 % LIGGGHTS looks: the run stops with that reason rather than break the neck early."""
    material = dict(validation.ELASTIC_ADHESIVE, cohesionEnergyDensity=50.0)
    separation = ThorntonNing(material=dict(material, radius=R))._separation_overlap(0.0)
    assert separation < -0.05 * R
    with pytest.raises(EngineError, match="adhesive neck would persist beyond the contact distance"):
        validation.wall_impact("liggghts", tmp_path, ThorntonNing, material, speed=1.0)


def test_an_addon_that_was_not_built_is_reported_with_the_fix(tmp_path, monkeypatch):
    """pip installs the plugin without the add-on when LIGGGHTS' headers are missing; the reason
    then names the package to install and the reinstall."""
    monkeypatch.setattr(library, "__file__", str(tmp_path / "library.py"))
    reason = library._load_addon()
    assert "not built" in reason and "libliggghts-dev" in reason and "pip install" in reason
