"""Servo walls (mtype 'mesh/surface/stress/servo') on real LIGGGHTS: a plate driven to a target
force comes to rest on a settled bed, which then pushes back with that force."""

import math
from pathlib import Path

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import params, simulation
from pygran_core.errors import ConfigError
from pygran_core.testing.solvers import require_solver

SQUARE = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes" / "square.stl"
G, R, DT = 9.81, 2e-4, 2e-6


def servo_bed(output, target, **servo):
    """48 spheres settle in a periodic 2 mm x 2 mm column on a floor (square.stl, 2 mm x 2 mm,
    a stress mesh) under a plate (the same square, 2 mm up) driven down onto them until they
    push back with ``target``."""
    require_solver(find_library)
    args = {"scale": 1e-3, "move": (0, 0, -1e-3), "com": (0, 0, 2e-3), "ctrlPV": "force"}
    args |= {"axis": (0, 0, -1), "target_val": target, "vel_max": 0.01, "kp": 1} | servo
    return simulation.DEM(
        engine="liggghts",
        model="HertzMindlin",
        box=(-1e-3, 1e-3, -1e-3, 1e-3, -2e-4, 3e-3),
        boundary=("p", "p", "f"),
        gravity=(G, 0, 0, -1),
        dt=DT,
        output=str(output),
        species=({"material": params.cohesionless, "radius": R},),
        mesh={
            "floor": {
                "file": str(SQUARE),
                "mtype": "mesh/surface/stress",
                "args": {"scale": 1e-3, "move": (0, 0, -3e-3)},
            },
            "plate": {"file": str(SQUARE), "mtype": "mesh/surface/stress/servo", "args": args},
        },
        traj={"pfile": None},
        progress=False,
    )


def test_servo_plate_comes_to_rest_on_the_bed_at_its_target_force(tmp_path):
    """Once at rest, the plate feels the target force (the mean of 20 readings over 2000 steps,
    within 5 %) and the floor the bed's weight plus that force; the bed no longer moves."""
    assert SQUARE.is_file(), f"the shared fixture {SQUARE} is missing"
    target = 2.5e-5  # about the bed's weight
    with servo_bed(tmp_path, target) as sim:
        # as many as fit clear of the floor and the plate, whole spheres in the block
        sim.insert(species=1, value=48, region=("block", -1e-3, 1e-3, -1e-3, 1e-3, 0, 1.95e-3))
        sim.run(80000)
        weight = sim.engine.extract("mass").sum() * G
        top = sim.extractCoords()[:, 2].max()
        plate, floor = [], []
        for _ in range(20):
            sim.run(100)
            plate.append(sim.engine.mesh_force("plate"))
            floor.append(sim.engine.mesh_force("floor"))
        moved = abs(sim.extractCoords()[:, 2].max() - top)
        count = len(sim.extractIds())
    assert count == 48
    assert weight == pytest.approx(48 * 4 / 3 * math.pi * R**3 * params.cohesionless["density"] * G, rel=1e-9)
    plate, floor = np.mean(plate, axis=0), np.mean(floor, axis=0)
    assert plate[2] == pytest.approx(target, rel=0.05)  # the bed pushes the plate up
    assert -floor[2] == pytest.approx(weight + target, rel=0.05)  # and the floor down
    assert moved < 0.01 * R


def test_servo_limits_and_misuse_are_refused(tmp_path):
    """LIGGGHTS moves a servo wall at most half the neighbour skin (here R) per step; a servo
    wall must be a wall while the simulation runs, and moveMesh cannot move it."""
    with pytest.raises(ConfigError, match=r"servo vel_max 60 m/s must be below skin / \(2 dt\) = 50 m/s"):
        servo_bed(tmp_path / "fast", 1e-5, vel_max=60)
    with servo_bed(tmp_path / "moved", 1e-5) as sim:
        with pytest.raises(ConfigError, match="'plate' is a servo wall"):
            sim.moveMesh("plate", linear=(0, 0, -0.01))
        with pytest.raises(ConfigError, match=r"servo vel_max 0.01 m/s must be below .* = 0.01 m/s"):
            sim.run(10, dt=0.01)
        sim.remove("plate")
        with pytest.raises(ConfigError, match="servo mesh 'plate' must be a wall while the simulation runs"):
            sim.run(10, dt=DT)


def test_servo_in_mode_auto_runs_every_chunk_with_its_set_up(tmp_path):
    """In mode auto LIGGGHTS sets the plate's speed in contact at each run's set-up from the
    smallest particle present (ratio r_min / dt), so no run chunk skips it ('pre no'); the
    run's last 3 steps are single steps, where the force on the servo is read."""
    with servo_bed(tmp_path, 1e-5, mode="auto", ratio=1e-3) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, R)
        sim.run(1000)
    text = (tmp_path / "in.pygran").read_text()
    assert "mode auto ratio 0.001" in text
    assert (
        text.count("run 100 post no") == 9
        and "run 97 post no\nrun 1 post no\nrun 1 post no\nrun 1 post no" in text
    )
    assert "pre no" not in text
