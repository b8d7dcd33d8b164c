"""Servo walls (``mtype='mesh/surface/stress/servo'``) on the native engine.

The script of ``tests/compat/test_plate_scripts.py``: a servo plate pressing a settled bed
comes to rest where the bed pushes back with the target force, on native as on LIGGGHTS, at
the same height; the controller is LIGGGHTS' (checked step by step on a plate alone against
the law of ``mesh_module_stress_servo.cpp``), and checkpoints carry it.
"""

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from pygran_native.solver import Solver

from PyGran import simulation
from pygran_core.errors import ConfigError, ServoWarning

MESHES = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes"
R, G = 2e-4, 9.81
SIDE = 1.2e-3  #: half the column's width (m); square.stl scaled by SIDE spans it at z = 3 SIDE
WEIGHT = 100 * 4 / 3 * np.pi * R**3 * 1000 * G  #: the bed's weight (N): 100 spheres, 1000 kg/m^3


def servo_press(engine, output):
    """100 spheres created at random settle on the floor under a servo plate 4 mm up that moves
    down at up to 2 cm/s until the bed pushes back with 10 times its weight; returns the mean
    of 20 readings of the plate's force over the last 2000 steps, how far the bed's top moved
    meanwhile, the bed's top and the simulation (closed)."""
    from PyGran.params import cohesionless

    cohesionless["coefficientRestitution"] = 0.5
    servo = {"com": (0, 0, 4e-3), "ctrlPV": "force", "axis": (0, 0, -1), "target_val": 10 * WEIGHT}
    params = {
        "engine": engine,
        "output": output,
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, 4.5e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (G, 0, 0, -1),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "mesh": {
            "plate": {
                "file": str(MESHES / "square.stl"),
                "mtype": "mesh/surface/stress/servo",
                "args": {"scale": SIDE, "move": (0, 0, 4e-3 - 3 * SIDE), **servo, "vel_max": 0.02, "kp": 1},
            }
        },
        "region": ("block", -SIDE, SIDE, -SIDE, SIDE, 0, 3.5e-3),
        "stages": {"press": 1e5, "read": 2e3},
    }
    sim = simulation.DEM(**params)
    with sim:
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        assert sim.createParticles(1, "random", 100, region=params["region"]) == 100
        sim.run(params["stages"]["press"], params["dt"])
        top = sim.extractCoords()[:, 2].max() + R
        forces = []
        for _ in range(20):
            sim.run(params["stages"]["read"] / 20, params["dt"])
            forces.append(sim.engine.mesh_force("plate"))
        now = sim.extractCoords()[:, 2].max() + R
    return np.mean(forces, axis=0), abs(now - top), now, sim


def require_liggghts() -> None:
    from pygran_liggghts.library import find_library

    from pygran_core.testing.solvers import require_solver

    require_solver(find_library)


@pytest.fixture(scope="module")
def pressed(tmp_path_factory):
    runs = {}

    def run(engine):
        if engine not in runs:
            if engine == "liggghts":
                require_liggghts()
            runs[engine] = servo_press(engine, str(tmp_path_factory.mktemp(engine) / "out"))
        return runs[engine]

    return run


def test_a_servo_plate_comes_to_rest_at_its_target_force(pressed):
    """Native: the mean force of the bed on the plate is the target within 5 % (measured:
    1.00001 times it), the bed's top moves less than 1 % of a radius over the readings, and
    the plate rests on it (its height within a tenth of a radius of the bed's top)."""
    force, moved, top, sim = pressed("native")
    assert force[2] == pytest.approx(10 * WEIGHT, rel=0.05)
    assert abs(force[0]) + abs(force[1]) < 0.05 * force[2]
    assert moved < 0.01 * R
    solver = sim.engine.solver
    plate = solver.mesh_triangles(sim.engine._mesh_walls["plate"])[:, :, 2]
    assert np.ptp(plate) < 1e-12  # it moved along its axis only: still flat
    assert plate.mean() == pytest.approx(top, abs=0.1 * R)


def test_native_and_liggghts_agree_on_the_plates_height(pressed):
    """The same script on both engines: the plate rests on the bed's top at heights within 3 %
    (measured: 1.082 mm on native, 1.102 mm on LIGGGHTS, 1.8 %; the random beds differ)."""
    native, liggghts = pressed("native"), pressed("liggghts")
    assert liggghts[0][2] == pytest.approx(10 * WEIGHT, rel=0.05)
    assert native[2] == pytest.approx(liggghts[2], rel=0.03)


def lattice_press(engine, output, kp):
    """25 spheres on a 5 x 5 square grid resting on the floor, with a servo plate 20 um above
    them (10 times their weight as target, vel_max 2 cm/s): the plate's force over 6 single
    steps after 10^5 steps, as fractions of the target. The bed has no randomness, so both
    engines start from the same state and must follow the same path."""
    from PyGran.params import cohesionless

    cohesionless["coefficientRestitution"] = 0.5
    grid = (np.arange(5) - 2) * 4.8e-4
    spheres = np.array([(x, y, R) for x in grid for y in grid])
    target = 10 * len(spheres) * 4 / 3 * np.pi * R**3 * 1000 * G
    top = 2 * R + 2e-5
    servo = {"com": (0, 0, top), "ctrlPV": "force", "axis": (0, 0, -1), "target_val": target}
    params = {
        "engine": engine,
        "output": output,
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, 4.5e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (G, 0, 0, -1),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "mesh": {
            "plate": {
                "file": str(MESHES / "square.stl"),
                "mtype": "mesh/surface/stress/servo",
                "args": {"scale": SIDE, "move": (0, 0, top - 3 * SIDE), **servo, "vel_max": 0.02, "kp": kp},
            }
        },
    }
    with simulation.DEM(**params) as sim, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ServoWarning)
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        sim.createParticles(1, "single", spheres)
        sim.run(1e5, params["dt"])
        warned = [str(w.message) for w in caught if issubclass(w.category, ServoWarning)]
        forces = []
        for _ in range(6):
            sim.run(1, params["dt"])
            forces.append(sim.engine.mesh_force("plate")[2] / target)
    return np.array(forces), warned


@pytest.mark.parametrize("kp", [0.1, 0.2])
def test_on_the_same_bed_the_plate_follows_liggghts_step_for_step(tmp_path, kp):
    """The controller and the plate's contacts are LIGGGHTS', the damping of the moving plate
    included: on the same lattice bed the plate's force equals LIGGGHTS' at every step (measured:
    to 1e-13 of the target) whether the controller settles (kp 0.1: the target to 1e-9) or not.
    With kp 0.2 the plate's own speed, through the contacts' damping, flips the force each step
    on both engines (measured: -4.79 and 6.77 times the target), as it does for kp 1.5 on
    LIGGGHTS with the random bed of the other tests (kp 1 there: native oscillates on some beds,
    LIGGGHTS on others; the beds differ). The gain that settles depends on the bed, so the run
    ends with a ServoWarning saying so, on both engines; none when the force settles."""
    require_liggghts()
    native, native_warned = lattice_press("native", str(tmp_path / "native"), kp)
    liggghts, liggghts_warned = lattice_press("liggghts", str(tmp_path / "liggghts"), kp)
    np.testing.assert_allclose(native, liggghts, rtol=0, atol=1e-9)
    if kp == 0.1:
        np.testing.assert_allclose(native, 1.0, rtol=0, atol=1e-6)
        assert native_warned == liggghts_warned == []
    else:
        assert np.all(np.abs(np.diff(native)) > 1.0) and native.min() < 0 < 1 < native.max()
        # the user is told, on both engines
        for warned in (native_warned, liggghts_warned):
            assert len(warned) == 1 and "servo wall 'plate' does not settle" in warned[0]
            assert "kp=0.2" in warned[0] and "Lower kp or vel_max" in warned[0]


def plate(threads=1, height=1e-3, **servo):
    """A solver with a square plate (two triangles, 2 mm wide) at ``height`` as a servo
    along -z (com at its centre)."""
    solver = Solver(
        [[-2e-3, -2e-3, 0], [2e-3, 2e-3, 4e-3]], gravity=(0, 0, -9.81), skin=2e-4, threads=threads
    )
    solver.set_contact_model("hertz", youngs=1e7, poisson=0.25, restitution=0.5, friction=0.5)
    corners = np.array(
        [[-1e-3, -1e-3, height], [1e-3, -1e-3, height], [1e-3, 1e-3, height], [-1e-3, 1e-3, height]]
    )
    mesh = solver.add_mesh(corners, [[0, 1, 2], [0, 2, 3]])
    settings = {
        "control": "force",
        "axis": (0, 0, -2),
        "target": 1e-3,
        "vel_max": 0.02,
        "com": (0, 0, height),
    }
    solver.set_servo(mesh, **(settings | servo))
    return solver, mesh


def test_the_controller_is_liggghts_pid_law_step_by_step():
    """A plate touching nothing: the process value is 0, so LIGGGHTS' law gives the speed
    ``v_max (kp e + ki sum(e dt)) / |target|`` along the axis with ``e = target`` (the set point
    is -target), saturated at v_max, after which the integral is reset by LIGGGHTS' inverted
    controller equation ``(-sign(v) sp - e kp) / ki``; the plate moves by dt times the speed of
    the step before. Compared step by step with that recurrence, to rounding."""
    dt, vmax, target, kp, ki = 1e-6, 0.02, 1e-3, 0.25, 2e5
    solver, mesh = plate(kp=kp, ki=ki)
    sp, z, v, integral = -target, 1e-3, 0.0, 0.0
    outputs = []
    for _ in range(12):
        solver.run(1, dt)
        z -= dt * v  # moves at the last output first, then the controller runs
        err = sp - 0.0
        integral += err * dt
        v = -vmax * (err * kp + integral * ki) / target
        if abs(v) > vmax:
            v = np.sign(v) * vmax
            integral = (-np.sign(v) * sp - err * kp) / ki
        state = solver.servo_state(mesh)
        assert state["velocity"] == pytest.approx([0, 0, -v], rel=1e-12, abs=1e-18)
        assert state["integral"] == pytest.approx(integral, rel=1e-12)
        assert state["com"][2] == pytest.approx(z, rel=1e-12)
        assert solver.mesh_triangles(mesh)[:, :, 2] == pytest.approx(np.full((2, 3), z), rel=1e-12)
        outputs.append(v)
    assert max(outputs) == vmax  # saturated at step 4 ...
    assert min(outputs) < 0  # ... when LIGGGHTS' anti-windup turns a PI servo back: reproduced


def test_a_torque_servo_turns_about_its_axis_through_com():
    """ctrlPV torque: touching nothing, the plate turns about the axis through com at
    ``kp vel_max / (largest vertex distance from the axis)`` rad/s; its vertices stay at
    their distance from the axis."""
    solver, mesh = plate(control="torque", axis=(0, 0, 1), kp=0.5)
    solver.run(1000, 1e-6)
    omega = 0.5 * 0.02 / np.sqrt(2e-6)  # the corners are sqrt(2) mm from the axis
    state = solver.servo_state(mesh)
    assert state["velocity"] == pytest.approx([0, 0, omega], rel=1e-12)
    assert state["angle"] == pytest.approx(999 * 1e-6 * omega, rel=1e-9)  # the first step at rest
    corners = solver.mesh_triangles(mesh).reshape(-1, 3)
    assert np.hypot(corners[:, 0], corners[:, 1]) == pytest.approx(np.sqrt(2e-6), rel=1e-12)
    turned = np.arctan2(corners[1, 1], corners[1, 0]) - np.arctan2(-1, 1)
    assert turned == pytest.approx(state["angle"], rel=1e-9)


def test_checkpoints_carry_the_controller_bitwise():
    """A plate pressing 25 spheres on 2 threads: stopped half-way and resumed from its state in
    a new solver, it ends bitwise where the uninterrupted run ends (the controller's integral,
    previous force and position travel with the state)."""

    def start():
        solver, mesh = plate(threads=2, height=3.03e-4, kp=0.5, ki=10.0, kd=1e-9)
        solver.add_plane((0, 0, 0), (0, 0, 1))
        grid = np.stack(np.meshgrid(*[np.arange(-2, 3) * 4e-4] * 2, indexing="ij"), -1).reshape(-1, 2)
        solver.add_particles(np.column_stack([grid, np.full(len(grid), 1.5e-4)]), 1.5e-4, densities=2500)
        return solver, mesh

    whole, mesh = start()
    whole.run(3000, 1e-6)
    half, _ = start()
    half.run(1500, 1e-6)
    resumed, _ = start()
    resumed.set_state(half.get_state())
    resumed.run(1500, 1e-6)
    assert whole.mesh_force(mesh)[0][2] > 0  # pressing
    for a, b in zip(whole.mesh_force(mesh), resumed.mesh_force(mesh)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(whole.positions, resumed.positions)
    assert whole.servo_state(mesh)["integral"] == resumed.servo_state(mesh)["integral"] != 0


def test_servo_mistakes_are_config_errors():
    solver, mesh = plate()
    with pytest.raises(ConfigError, match="vel_max"):
        solver.run(1, 1e-2)  # 0.02 m/s x 10 ms is more than half the skin
    with pytest.raises(ConfigError, match="servo wall"):
        solver.set_mesh_motion(mesh, velocity=(0, 0, 1))
    with pytest.raises(ConfigError, match="kp, ki, kd"):
        plate(kp=0.0)
    with pytest.raises(ConfigError, match="ratio"):
        plate(mode="auto")


def test_a_stress_mesh_carries_the_weight_of_the_bed_on_it(tmp_path):
    """``mtype='mesh/surface/stress'``: 30 spheres settled on a mesh floor (square.stl) push it
    down with their weight (force along -z, 1 %), and a plain mesh has no force summed."""
    from PyGran.params import cohesionless

    cohesionless["coefficientRestitution"] = 0.3
    floor = {"file": str(MESHES / "square.stl"), "args": {"scale": SIDE, "move": (0, 0, -3 * SIDE)}}
    params = {
        "engine": "native",
        "output": str(tmp_path / "out"),
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, 3e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (G, 0, 0, -1),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "mesh": {
            "floor": floor | {"mtype": "mesh/surface/stress"},
            "lid": floor | {"args": {"scale": SIDE, "move": (0, 0, -SIDE)}},
        },
    }
    with simulation.DEM(**params) as sim:
        sim.createParticles(1, "random", 30, region=("block", -SIDE, SIDE, -SIDE, SIDE, R, 2e-3))
        sim.run(1.2e5, params["dt"])  # 0.24 s: the last bounces are over after 0.2 s
        force = sim.engine.mesh_force("floor")
        weight = sim.engine.extract("mass").sum() * G
        with pytest.raises(ConfigError, match="mesh/surface/stress"):
            sim.engine.mesh_force("lid")
    assert force == pytest.approx([0, 0, -weight], rel=1e-2, abs=1e-2 * weight)  # measured: 1e-8


# The servo plate of ``plate`` pressing spheres on 3 threads (on one CPU when told to): the plate's
# force and the spheres' positions to a .npy file.
THREADS = """
import os, sys
import numpy as np
from pygran_native.solver import Solver

if sys.argv[2] == "one-cpu":
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
s = Solver([[-2e-3, -2e-3, 0], [2e-3, 2e-3, 4e-3]], gravity=(0, 0, -9.81), skin=2e-4, threads=3)
s.set_contact_model("hertz", youngs=1e7, poisson=0.25, restitution=0.5, friction=0.5)
corners = np.array([[-2e-3, -2e-3, 0], [2e-3, -2e-3, 0], [2e-3, 2e-3, 0], [-2e-3, 2e-3, 0]]) + [0, 0, 3.05e-4]
mesh = s.add_mesh(corners, [[0, 1, 2], [0, 2, 3]])
s.set_servo(mesh, control="force", axis=(0, 0, -1), target=1e-3, vel_max=0.02, com=(0, 0, 3.05e-4), kp=0.5)
s.add_plane((0, 0, 0), (0, 0, 1))
grid = np.stack(np.meshgrid(*[np.arange(-4, 5) * 4.2e-4] * 2, indexing="ij"), -1).reshape(-1, 2)
s.add_particles(np.column_stack([grid, np.full(len(grid), 1.5e-4)]), 1.5e-4, densities=2500)
s.run(4000, 1e-6)
np.save(sys.argv[1], np.vstack([s.mesh_force(mesh)[0], s.positions]))
"""


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this system")
def test_the_servo_force_does_not_depend_on_which_thread_runs_a_block(tmp_path):
    """The plate's force is summed over the blocks in block order: on 3 threads, the same bits
    whether the threads share one CPU or not."""

    def press(cpus):
        out = tmp_path / f"{cpus}.npy"
        subprocess.run([sys.executable, "-c", THREADS, str(out), cpus], check=True)
        return np.load(out)

    spread = press("all")
    assert spread[0, 2] > 0  # pressing
    np.testing.assert_array_equal(press("one-cpu"), spread)


def test_mode_auto_cruises_at_vel_max_then_follows_liggghts_piecewise_law():
    """mode auto: touching nothing the plate cruises at vel_max; in contact its speed is
    ``-kp(e) e`` with ``e = (sp - F.axis) / |sp|`` and LIGGGHTS' piecewise gain ``kp`` from
    0.1 to 1 times ``ratio r_min / dt`` as |e| goes from 0.9 to 1 (checked at every step of a
    plate pressing 25 spheres against its reading of the force, to rounding)."""
    dt, ratio, r = 1e-6, 1e-3, 1.5e-4
    solver, mesh = plate(height=3.2e-4, mode="auto", ratio=ratio, target=1e-4)
    grid = np.stack(np.meshgrid(*[np.arange(-2, 3) * 4e-4] * 2, indexing="ij"), -1).reshape(-1, 2)
    solver.add_particles(np.column_stack([grid, np.full(len(grid), r)]), r, densities=2500)
    solver.add_plane((0, 0, 0), (0, 0, 1))
    solver.run(1, dt)
    assert solver.servo_state(mesh)["velocity"] == pytest.approx([0, 0, -0.02], rel=1e-12)  # cruise
    slow, touched = ratio * r / dt, 0
    for _ in range(3000):
        solver.run(1, dt)
        force = solver.mesh_force(mesh)[0]
        if force[2] == 0:
            continue
        touched += 1
        err = (-1e-4 + force[2]) / 1e-4  # the axis is -z
        gain = (
            0.1 * slow
            if abs(err) <= 0.9
            else slow
            if abs(err) >= 1
            else 0.1 * slow + 0.9 * slow * (abs(err) - 0.9) / 0.1
        )
        speed = min(abs(gain * err), slow) * np.sign(-gain * err)
        assert solver.servo_state(mesh)["velocity"] == pytest.approx([0, 0, -speed], rel=1e-9, abs=1e-15)
    assert touched > 100


def servo_study(output, restart):
    """A servo plate pressing 30 spheres through the front end, with checkpoints; the end state."""
    from PyGran.params import cohesionless

    servo = {"com": (0, 0, 9e-4), "ctrlPV": "force", "axis": (0, 0, -1), "target_val": 2 * WEIGHT}
    params = {
        "engine": "native",
        "output": str(output),
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, 2e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (G, 0, 0, -1),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "restart": restart,
        "threads": 2,
        "mesh": {
            "plate": {
                "file": str(MESHES / "square.stl"),
                "mtype": "mesh/surface/stress/servo",
                "args": {"scale": SIDE, "move": (0, 0, 9e-4 - 3 * SIDE), **servo, "vel_max": 0.05, "kp": 1},
            }
        },
    }
    with simulation.DEM(**params) as sim:
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        sim.createParticles(1, "random", 30, region=("block", -SIDE, SIDE, -SIDE, SIDE, R, 8e-4))
        sim.run(3000)
        sim.run(3000)
        return (
            sim.extractCoords(),
            sim.engine.mesh_force("plate"),
            sim.engine.solver.mesh_triangles(sim.engine._mesh_walls["plate"]),
        )


def test_a_servo_study_resumes_bitwise_from_its_checkpoint(tmp_path):
    """Through the front end: resumed from the checkpoint of step 4500 (the plate pressing the
    bed), the spheres, the plate's force and its triangles end bitwise as the whole run's."""
    whole = servo_study(tmp_path / "a", (1500, "restart", "restart.*.h5"))
    resumed = tmp_path / "b"
    (resumed / "restart").mkdir(parents=True)
    name = "restart.4500.h5"
    (resumed / "restart" / name).write_bytes((tmp_path / "a" / "restart" / name).read_bytes())
    again = servo_study(resumed, (1500, "restart", "restart.*.h5", True, name))
    assert whole[1][2] > 0  # pressing
    for a, b in zip(whole, again):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("mistake", ["fast", "moved", "not-a-wall"])
def test_servo_mistakes_in_a_script_are_config_errors(tmp_path, mistake):
    """As on LIGGGHTS: vel_max >= skin / (2 dt) (at DEM()), moveMesh on a servo plate, and a
    run while the servo plate is not a wall ('import': False) are ConfigErrors naming the fix."""
    from PyGran.params import cohesionless

    servo = {"com": (0, 0, 1e-3), "ctrlPV": "force", "axis": (0, 0, -1), "target_val": 1e-4}
    plate = {
        "file": str(MESHES / "square.stl"),
        "mtype": "mesh/surface/stress/servo",
        "args": {"scale": SIDE, "move": (0, 0, 1e-3 - 3 * SIDE), **servo, "kp": 1},
    }
    plate["args"]["vel_max"] = 1e3 if mistake == "fast" else 0.02
    if mistake == "not-a-wall":
        plate["import"] = False
    params = {
        "engine": "native",
        "output": str(tmp_path / "out"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, 2e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "mesh": {"plate": plate},
    }
    message = {"fast": "vel_max", "moved": "servo wall", "not-a-wall": "setupWall"}[mistake]
    with pytest.raises(ConfigError, match=message):
        with simulation.DEM(**params) as sim:
            if mistake == "moved":
                sim.moveMesh("plate", linear=(0, 0, -0.01))
            sim.run(10)
