"""PyGran 1.x scripts with a plate over a settled bed, run unchanged on native and LIGGGHTS.

A plate moved down at constant speed (``moveMesh(name, linear=...)``) compresses the bed,
and the two engines agree on its height; a servo plate (``mtype``
``mesh/surface/stress/servo``) driven to a target force comes to rest where the bed pushes
back with that force (on native and LIGGGHTS).
"""

from pathlib import Path

import numpy as np
import pytest

from PyGran import simulation

MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"
ENGINES = ["native", "liggghts"]
R, G = 2e-4, 9.81
#: The column (m): periodic in x and y, a floor at z = 0.
SIDE = 1.2e-3
#: square.stl is a 2 x 2 square at z = 3: scaled by SIDE it spans the column at z = 3 SIDE.
SQUARE_Z = 3


def require(engine):
    if engine == "liggghts":
        from pygran_liggghts.library import find_library

        from pygran_core.testing.solvers import require_solver

        require_solver(find_library)


def column(engine, output, plate, top):
    """The params dict shared by both scripts: spheres of 0.2 mm created at random below
    ``top``, a plate (``plate``: its mesh entry) above them."""
    from PyGran.params import cohesionless

    cohesionless["coefficientRestitution"] = 0.5  # settles sooner
    return {
        "engine": engine,
        "output": output,
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, -R, top + 1e-3),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (G, 0, 0, -1),
        "dt": 2e-6,
        "traj": {"pfile": None},
        "mesh": {"plate": plate},
        "region": ("block", -SIDE, SIDE, -SIDE, SIDE, 0, top),
    }


def compress(engine, output):
    """200 spheres settle on the floor; a plate 7.1 mm up then moves down at 5 cm/s until it
    is at 96 % of the settled bed's height, stops (its motion removed) and holds."""
    params = column(
        engine,
        output,
        {
            "file": str(MESHES / "square.stl"),
            "mtype": "mesh/surface",
            "args": {"scale": SIDE, "move": (0, 0, 3.5e-3)},
        },
        top=7e-3,
    )
    params |= {"stages": {"settle": 4e4, "hold": 1e4}, "plate_speed": 0.05, "squeeze": 0.98}
    sim = simulation.DEM(**params)
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    created = sim.createParticles(1, "random", 200, region=params["region"])
    sim.run(params["stages"]["settle"], params["dt"])
    settled = sim.extractCoords()
    plate = SQUARE_Z * SIDE + 3.5e-3
    stop = params["squeeze"] * 2 * settled[:, 2].mean()
    steps = (plate - stop) / params["plate_speed"] / params["dt"]  # a float, as scripts have it
    motion = sim.moveMesh("plate", linear=(0, 0, -params["plate_speed"]))
    sim.run(steps, params["dt"])
    sim.remove(motion)
    sim.run(params["stages"]["hold"], params["dt"])
    pressed = sim.extractCoords()
    sim.close()
    final = plate - params["plate_speed"] * int(steps) * params["dt"]
    return created, settled, pressed, final


@pytest.fixture(scope="module")
def compressed(tmp_path_factory):
    """Each engine's run of :func:`compress`, made once for the tests of this module."""
    runs = {}

    def run(engine):
        if engine not in runs:
            require(engine)
            runs[engine] = compress(engine, str(tmp_path_factory.mktemp(engine) / "out"))
        return runs[engine]

    return run


def height(positions):
    """The bed's height: twice its spheres' mean centre height."""
    return 2 * float(positions[:, 2].mean())


@pytest.mark.parametrize("engine", ENGINES)
def test_a_moving_plate_compresses_a_settled_bed(engine, compressed):
    """Nothing lost, every sphere under the plate (overlapping it by at most 20 % of a radius)
    and on the floor, and the bed at least 2 % lower than it settled."""
    created, settled, pressed, plate = compressed(engine)
    assert created == 200 and len(settled) == len(pressed) == 200
    assert pressed[:, 2].max() + R < plate + 0.2 * R
    assert pressed[:, 2].min() > 0.8 * R
    assert height(pressed) < 0.98 * height(settled)
    assert plate < pressed[:, 2].max() + R  # the plate presses on the bed


def test_the_engines_agree_on_the_bed_height(compressed):
    """The same script on native and LIGGGHTS: the settled and the compressed bed heights
    agree within 3 %."""
    native, liggghts = compressed("native"), compressed("liggghts")
    for stage in (1, 2):  # settled, pressed
        assert height(native[stage]) == pytest.approx(height(liggghts[stage]), rel=0.03)


def servo_press(engine, output, target):
    """100 spheres settle on the floor under a servo plate 4 mm up that moves down at up to
    2 cm/s until the bed pushes back with ``target`` (N)."""
    servo = {"com": (0, 0, 4e-3), "ctrlPV": "force", "axis": (0, 0, -1), "target_val": target}
    plate = {
        "file": str(MESHES / "square.stl"),
        "mtype": "mesh/surface/stress/servo",
        "args": {"scale": SIDE, "move": (0, 0, 4e-3 - SQUARE_Z * SIDE), **servo, "vel_max": 0.02, "kp": 1},
    }
    params = column(engine, output, plate, top=3.5e-3) | {"stages": {"press": 1e5, "read": 2e3}}
    return simulation.DEM(**params), params


@pytest.mark.parametrize("engine", ENGINES)
def test_a_servo_plate_comes_to_rest_at_its_target_force(engine, tmp_path):
    """Ten times the bed's weight as target (the plate's damping by the contacts at vel_max is
    then well below it, so the plate does not chatter): at rest, the mean of 20 readings of the
    force the spheres exert on the plate over 2000 steps is the target within 5 %, and the bed
    no longer moves."""
    require(engine)
    weight = 100 * 4 / 3 * np.pi * R**3 * 1000 * G  # cohesionless: 1000 kg/m^3
    sim, params = servo_press(engine, str(tmp_path / "out"), 10 * weight)
    with sim:
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        assert sim.createParticles(1, "random", 100, region=params["region"]) == 100
        sim.run(params["stages"]["press"], params["dt"])
        top = sim.extractCoords()[:, 2].max()
        forces = []
        for _ in range(20):
            sim.run(params["stages"]["read"] / 20, params["dt"])
            forces.append(sim.engine.mesh_force("plate"))
        moved = abs(sim.extractCoords()[:, 2].max() - top)
        assert sim.engine.extract("mass").sum() * G == pytest.approx(weight, rel=1e-9)
    force = np.mean(forces, axis=0)
    assert force[2] == pytest.approx(10 * weight, rel=0.05)  # the bed pushes the plate up
    assert moved < 0.01 * R
