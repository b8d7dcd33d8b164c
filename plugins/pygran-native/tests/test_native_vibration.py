"""``moveMesh(viblin=..., vibrot=...)`` on the native engine: LIGGGHTS' ``move/mesh viblin``
and ``vibrot`` (a sum of harmonics: amplitude, phase, period each), in closed form, and a
plate vibrated under a sphere throws it as high as on LIGGGHTS."""

from pathlib import Path

import numpy as np
import pytest
from pygran_native.solver import Solver

from PyGran import simulation
from pygran_core.errors import ConfigError

MESHES = Path(__file__).resolve().parents[3] / "tests" / "data" / "meshes"
AMPLITUDES, PHASES, PERIODS = (2e-4, -5e-5), (0.3, -1.2), (4e-3, 1.5e-3)


def square():
    """A solver with a square mesh (2 mm wide, two triangles) at z = 1 mm, and its corners."""
    solver = Solver([[-2e-3, -2e-3, 0], [2e-3, 2e-3, 4e-3]], skin=2e-4)
    solver.set_contact_model("hertz", youngs=1e7, poisson=0.25, restitution=0.5)
    corners = np.array([[-1e-3, -1e-3, 1e-3], [1e-3, -1e-3, 1e-3], [1e-3, 1e-3, 1e-3], [-1e-3, 1e-3, 1e-3]])
    mesh = solver.add_mesh(corners, [[0, 1, 2], [0, 2, 3]])
    return solver, mesh, corners[[0, 1, 2, 0, 2, 3]]


def closed_form(t):
    """LIGGGHTS' displacement (or angle) ``sum_j A_j (cos(w_j t + phi_j) - cos(phi_j))``."""
    w = 2 * np.pi / np.array(PERIODS)
    return float(np.sum(np.array(AMPLITUDES) * (np.cos(w * t + PHASES) - np.cos(PHASES))))


def test_viblin_moves_the_vertices_by_the_closed_form():
    """Two harmonics along (1, 0, 2)/sqrt(5), started at t0 = 0.7 ms: at 9 times over a
    period the vertices are the start ones plus the closed form along the axis (1e-12)."""
    solver, mesh, start = square()
    solver.run(700, 1e-6)
    t0 = solver.time
    solver.set_mesh_vibration(mesh, "viblin", (1, 0, 2), AMPLITUDES, PHASES, PERIODS)
    axis = np.array([1, 0, 2]) / np.sqrt(5)
    for _ in range(9):
        solver.run(500, 1e-6)
        expected = start + closed_form(solver.time - t0) * axis
        np.testing.assert_allclose(solver.mesh_triangles(mesh).reshape(-1, 3), expected, rtol=1e-12, atol=0)


def test_vibrot_turns_the_vertices_by_the_closed_form():
    """About z through (1 mm, 0, 0): the vertices turn by the closed-form angle (1e-12)."""
    solver, mesh, start = square()
    solver.set_mesh_vibration(mesh, "vibrot", (0, 0, 1), AMPLITUDES, PHASES, PERIODS, origin=(1e-3, 0, 0))
    for _ in range(9):
        solver.run(500, 1e-6)
        angle = closed_form(solver.time)
        c, s = np.cos(angle), np.sin(angle)
        rel = start - [1e-3, 0, 0]
        expected = np.column_stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1], rel[:, 2]])
        expected += [1e-3, 0, 0]
        np.testing.assert_allclose(
            solver.mesh_triangles(mesh).reshape(-1, 3), expected, rtol=1e-12, atol=1e-12 * 1e-3
        )


def test_a_vibration_is_replaced_by_a_stop_and_checked():
    solver, mesh, start = square()
    solver.set_mesh_vibration(mesh, "viblin", (0, 0, 1), AMPLITUDES, PHASES, PERIODS)
    solver.run(300, 1e-6)
    moved = solver.mesh_triangles(mesh)
    solver.set_mesh_motion(mesh)  # stops where it is
    solver.run(300, 1e-6)
    np.testing.assert_array_equal(solver.mesh_triangles(mesh), moved)
    assert not np.allclose(moved.reshape(-1, 3), start)
    with pytest.raises(ConfigError, match="periods"):
        solver.set_mesh_vibration(mesh, "viblin", (0, 0, 1), (1e-4,), (0,), (0,))
    with pytest.raises(ConfigError, match="kind"):
        solver.set_mesh_vibration(mesh, "shake", (0, 0, 1), (1e-4,), (0,), (1e-3,))


SIDE = 1.2e-3  #: half the column's width (m); square.stl scaled by SIDE spans it at z = 3 SIDE
R = 2e-4


def bounce(engine, output):
    """A sphere of 0.2 mm resting on a plate that vibrates up and down (viblin, 100 Hz, 0.1 mm:
    4 g); the highest its bottom gets above the plate's mean height in 15 ms, in m."""
    from PyGran.params import cohesionless

    params = {
        "engine": engine,
        "output": output,
        "boundary": ("p", "p", "f"),
        "box": (-SIDE, SIDE, -SIDE, SIDE, 0, 1e-2),
        "species": ({"material": cohesionless, "radius": R},),
        "gravity": (9.81, 0, 0, -1),
        "dt": 1e-6,
        "traj": {"pfile": None},
        "mesh": {
            "plate": {
                "file": str(MESHES / "square.stl"),
                "args": {"scale": SIDE, "move": (0, 0, 1e-3 - 3 * SIDE)},
            }
        },
    }
    sim = simulation.DEM(**params)
    with sim:
        # right above the vertex where 8 of the plate's triangles meet
        assert sim.createParticles(1, "single", 0.0, 0.0, 1e-3 + R) == 1
        sim.moveMesh(
            "plate", viblin=("axis", 0, 0, 1), order=1, amplitude=1e-4, phase=-np.pi / 2, period=1e-2
        )
        heights = []
        for _ in range(150):
            sim.run(100, params["dt"])
            heights.append(sim.extractCoords()[0, 2] - R - 1e-3)
    return max(heights)


def test_a_vibrated_plate_throws_a_sphere_as_high_as_on_liggghts(tmp_path):
    """The plate's displacement is ``A sin(2 pi t / T)`` (phase -pi/2): it starts up at
    ``A 2 pi / T`` = 6.3 cm/s, knocks the sphere up (restitution 0.9) and the sphere flies well
    above the amplitude; the highest point in 15 ms agrees with LIGGGHTS' within 2 % (measured:
    0.731 mm on both, 1e-5 apart)."""
    from pygran_liggghts.library import find_library

    from pygran_core.testing.solvers import require_solver

    native = bounce("native", str(tmp_path / "native"))
    assert native > 2e-4
    require_solver(find_library)
    assert native == pytest.approx(bounce("liggghts", str(tmp_path / "liggghts")), rel=0.02)


def test_checkpoints_carry_a_vibration_bitwise():
    """Spheres on a vibrating square, stopped half-way and resumed from the state in a new
    solver: the same bits as the uninterrupted run."""

    def start():
        solver, mesh, _ = square()
        solver.set_mesh_vibration(mesh, "vibrot", (0, 1, 1), AMPLITUDES, PHASES, PERIODS, origin=(0, 0, 1e-3))
        grid = np.stack(np.meshgrid(*[np.arange(-1, 2) * 5e-4] * 2, indexing="ij"), -1).reshape(-1, 2)
        solver.add_particles(np.column_stack([grid, np.full(len(grid), 1.2e-3)]), 2e-4, densities=2500)
        return solver, mesh

    whole, mesh = start()
    whole.run(2000, 1e-6)
    half, _ = start()
    half.run(1000, 1e-6)
    resumed, _ = start()
    resumed.set_state(half.get_state())
    resumed.run(1000, 1e-6)
    np.testing.assert_array_equal(whole.mesh_triangles(mesh), resumed.mesh_triangles(mesh))
    np.testing.assert_array_equal(whole.velocities, resumed.velocities)
    assert np.abs(whole.forces[:, 2]).max() > 0
