"""The native solver's results are bitwise those of reference runs: a guard for changes to the
compiled core that must not change its arithmetic (restructuring, renaming, splitting files).

Four scenarios cover every kernel: a periodic settle (hertz, rolling epsd, cohesion,
limitForce, viscous damping, two types, a plane, an outside cylinder), a periodic shear of
hertz spheres without rolling resistance (friction on some pairs and not others, cohesion,
limitForce, sliding and sticking contacts; the pair loop's batched path), a hopper (thornton-ning
with adhesion, rolling epsd2, a cylinder, a vibrating funnel mesh, a rotating and wiggling
stirrer whose force is summed, a force servo lid, particles lost through the bottom) and a mixer
(hooke, rolling cdt, a torque servo in mode auto, a vibrot mesh, planes). Each runs with one and
two threads, with removals (particles, a wall), an insertion, new radii and a checkpoint round
trip between two runs; every output array and every entry of ``get_state`` is compared with
``tests/data/solver_bitwise_<case>.npz``.

The references hold for x86-64 Linux (glibc's libm); ``python tests/test_solver_bitwise.py``
writes them anew from the build in use (see tests/data/README.md).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from pygran_native.solver import Solver

from pygran_core.errors import ConfigError

DATA = Path(__file__).parent / "data"
THREADS = (1, 2)


def frustum(r_top: float, r_bottom: float, z_top: float, z_bottom: float, segments: int = 12):
    """Open cone between two rings about the z axis: vertices and triangles."""
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(phi), np.sin(phi)], 1)
    top = np.column_stack([r_top * ring, np.full(segments, z_top)])
    bottom = np.column_stack([r_bottom * ring, np.full(segments, z_bottom)])
    k = np.arange(segments)
    nxt = (k + 1) % segments
    tris = np.concatenate(
        [np.stack([k, nxt, segments + k], 1), np.stack([nxt, segments + nxt, segments + k], 1)]
    )
    return np.concatenate([top, bottom]), tris


def rectangle(corner, u, v):
    """Two triangles spanning ``corner + a u + b v`` for a, b in [0, 1]."""
    c, u, v = (np.asarray(a, float) for a in (corner, u, v))
    return np.array([c, c + u, c + u + v, c + v]), np.array([[0, 1, 2], [0, 2, 3]])


def lattice(lo, hi, spacing: float, rng: np.random.Generator, jitter: float) -> np.ndarray:
    """Points of a cubic lattice in the box [lo, hi], shifted at random by up to ``jitter``."""
    axes = [np.arange(a + spacing / 2, b - spacing / 2 + 1e-12, spacing) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    return grid + rng.uniform(-jitter, jitter, grid.shape)


def restart(s: Solver, **kwargs) -> Solver:
    """A new solver continuing from ``s``'s checkpoint."""
    fresh = Solver(**kwargs)
    fresh.set_state(s.get_state())
    return fresh


def settle(threads: int) -> Solver:
    rng = np.random.default_rng(1)
    a = 2.1e-3
    box = dict(
        box=[[0, 0, 0], [6 * a, 6 * a, 9 * a]],
        periodic=(True, True, False),
        gravity=(0, 0, -9.81),
        skin=3e-4,
        threads=threads,
    )
    s = Solver(**box)
    s.set_contact_model(
        "hertz",
        youngs=[5e6, 8e6],
        poisson=[0.45, 0.3],
        restitution=[0.5, 0.7],
        friction=[0.5, 0.3],
        rolling_friction=[0.2, 0.1],
        rolling="epsd",
        rolling_damping=[0.3, 0.5],
        limit_force=True,
        cohesion_energy=[2e3, 1e3],
    )
    s.set_viscous([1e-5, 0.0])
    s.add_plane((0, 0, 0), (0, 0, 1), type=1)
    s.add_cylinder("z", (3 * a, 3 * a), 0.4e-3, type=1, inside=False)
    x = lattice([0, 0, 0], [6 * a, 6 * a, 6 * a], a, rng, 0.03e-3)
    n = len(x)
    s.add_particles(
        x,
        rng.uniform(0.85e-3, 1.0e-3, n),
        densities=2500,
        types=rng.integers(0, 2, n),
        velocities=rng.normal(0, 0.2, (n, 3)) - [0, 0, 0.3],
        omegas=rng.normal(0, 50, (n, 3)),
    )
    s.run(150, 1e-5)
    s.remove_particles([3, 40])
    s.set_omegas([7], [[0, 300, 0]])
    s = restart(s, **box)
    s.set_radii([10, 11], [0.95e-3, 0.9e-3])
    s.add_particles([[2 * a, 2 * a, 8 * a]], 0.9e-3, densities=2500, velocities=[[0, 0, -1]])
    s.run(150, 1e-5)
    return s


#: the shear case's materials: Young's modulus, Poisson ratio, restitution, friction, cohesion
SHEAR_MATERIALS = ((5e6, 0.45, 0.4, 0.6, 1e3), (7e7, 0.3, 0.8, 0.0, 0.0))


def shear(threads: int, materials=SHEAR_MATERIALS) -> Solver:
    """The sheared bed; the particles of type k (random) and the lid of type 1 taken modulo the
    number of ``materials``."""
    rng = np.random.default_rng(4)
    a = 2.1e-3
    box = dict(
        box=[[0, 0, 0], [6 * a, 6 * a, 7 * a]], periodic=(True, True, False), skin=3e-4, threads=threads
    )
    s = Solver(gravity=(0, 0, -9.81), **box)
    youngs, poisson, restitution, friction, cohesion = (list(column) for column in zip(*materials))
    s.set_contact_model(
        "hertz",
        youngs=youngs,
        poisson=poisson,
        restitution=restitution,
        friction=friction,
        limit_force=True,
        cohesion_energy=cohesion,
    )
    s.add_plane((0, 0, 0), (0, 0, 1), type=0)
    s.add_plane((0, 0, 5 * a), (0, 0, -1), type=1 % len(materials))  # a lid: the bed stays dense
    x = lattice([0, 0, 0], [6 * a, 6 * a, 5 * a], a, rng, 0.02e-3)
    n = len(x)
    s.add_particles(
        x,
        rng.uniform(0.98e-3, 1.07e-3, n),
        densities=2500,
        types=rng.integers(0, 2, n) % len(materials),
        velocities=np.column_stack([0.5 * x[:, 2] / (5 * a), np.zeros(n), np.zeros(n)])
        + rng.normal(0, 0.1, (n, 3)),
        omegas=rng.normal(0, 100, (n, 3)),
    )
    s.run(200, 1e-5)
    s = restart(s, gravity=(0, 0, -9.81), **box)
    s.run(200, 1e-5)
    return s


def hopper(threads: int) -> Solver:
    rng = np.random.default_rng(2)
    box = dict(
        box=[[-9e-3, -9e-3, 0], [9e-3, 9e-3, 26e-3]], gravity=(0, 0, -9.81), skin=4e-4, threads=threads
    )
    s = Solver(**box)
    s.set_contact_model(
        "thornton-ning",
        youngs=[5e6, 7e6],
        poisson=[0.4, 0.3],
        friction=[0.4, 0.5],
        rolling_friction=[0.1, 0.2],
        rolling="epsd2",
        cohesion_energy=[0.05, 0.02],
        yield_pressure=[2e5, 3e5],
    )
    s.add_cylinder("z", (0, 0), 8e-3, type=1)
    funnel = s.add_mesh(*frustum(8e-3, 3e-3, 10e-3, 2e-3), type=1)
    s.set_mesh_vibration(funnel, "viblin", (0, 0, 1), [2e-4, 1e-4], [0.0, 0.5], [1e-3, 4e-4])
    stirrer = s.add_mesh(*rectangle((-4e-3, 0, 7e-3), (8e-3, 0, 0), (0, 0, 11e-3)), type=1)
    s.set_mesh_motion(
        stirrer, angular_velocity=(0, 0, 300), origin=(0, 0, 0), amplitude=(2e-4, 0, 0), period=1.5e-3
    )
    s.set_stress(stirrer, reference=(0, 0, 15e-3))
    lid = s.add_mesh(*rectangle((-7e-3, -7e-3, 19.5e-3), (14e-3, 0, 0), (0, 14e-3, 0)), type=1)
    s.set_servo(
        lid, control="force", axis=(0, 0, -1), target=0.02, vel_max=1.5, com=(0, 0, 19.5e-3), kp=2.0, ki=0.1
    )
    x = lattice([-6e-3, -6e-3, 4e-3], [6e-3, 6e-3, 18.5e-3], 2.05e-3, rng, 0.03e-3)
    x = x[np.hypot(x[:, 0], x[:, 1]) + 0.95e-3 < np.maximum(3e-3 + (x[:, 2] - 2e-3) * 5 / 8, 3e-3)]
    x = x[np.hypot(x[:, 0], x[:, 1]) < 6.9e-3]
    x = x[(np.abs(x[:, 1]) > 1.1e-3) | (x[:, 2] < 6e-3)]  # not inside the stirrer
    n = len(x)
    s.add_particles(
        x,
        rng.uniform(0.8e-3, 0.95e-3, n),
        densities=2500,
        types=rng.integers(0, 2, n),
        velocities=rng.normal(0, 0.1, (n, 3)) - [[0, 0, 1.5 if z < 9e-3 else 0.2] for z in x[:, 2]],
    )
    s.run(200, 1e-5)
    s.remove_particles([0])
    s = restart(s, **box)
    s.add_particles([[0, -4e-3, 20e-3]], 0.9e-3, densities=2500, types=1)
    s.run(200, 1e-5)
    return s


def mixer(threads: int) -> Solver:
    rng = np.random.default_rng(3)
    box = dict(
        box=[[-8e-3, -8e-3, 0], [8e-3, 8e-3, 12e-3]], gravity=(0, 0, -9.81), skin=4e-4, threads=threads
    )
    s = Solver(**box)
    s.set_contact_model(
        "hooke",
        youngs=[5e6, 6e6],
        poisson=0.4,
        restitution=[0.6, 0.8],
        friction=0.4,
        rolling_friction=[0.05, 0.1],
        rolling="cdt",
        cohesion_energy=[500.0, 0.0],
        characteristic_velocity=1.0,
    )
    s.add_plane((0, 0, 0), (0, 0, 1), type=1)
    s.add_plane((0, 0, 11e-3), (0, 0, -1), type=1)
    s.add_cylinder("z", (0, 0), 7.5e-3, type=1)
    paddle = s.add_mesh(*rectangle((0, -0.5e-3, 0.2e-3), (6e-3, 0, 0), (0, 0, 8e-3)), type=1)
    s.set_servo(
        paddle,
        control="torque",
        axis=(0, 0, 1),
        target=1e-5,
        vel_max=0.5,
        com=(0, 0, 4e-3),
        mode="auto",
        ratio=0.05,
    )
    ring = s.add_mesh(*frustum(7.4e-3, 5.5e-3, 9.5e-3, 7e-3, segments=10), type=1)
    s.set_mesh_vibration(ring, "vibrot", (0, 0, 1), [0.2], [0.3], [2e-3], origin=(0, 0, 0))
    x = lattice([-6e-3, -6e-3, 0.2e-3], [6e-3, 6e-3, 6e-3], 1.9e-3, rng, 0.03e-3)
    x = x[(np.hypot(x[:, 0], x[:, 1]) < 6.4e-3) & ((np.abs(x[:, 1] + 0.5e-3) > 1.1e-3) | (x[:, 0] < -1e-3))]
    n = len(x)
    s.add_particles(
        x,
        rng.uniform(0.88e-3, 0.98e-3, n),
        masses=rng.uniform(4e-6, 8e-6, n),
        types=rng.integers(0, 2, n),
        velocities=rng.normal(0, 1.0, (n, 3)),
    )
    s.run(150, 1e-5)
    s.remove_wall(1)  # the lid plane
    s = restart(s, **box)
    s.run(100, 1e-5)  # the paddle is in contact at the end
    return s


CASES: dict[str, Callable[[int], Solver]] = {
    "settle": settle,
    "shear": shear,
    "hopper": hopper,
    "mixer": mixer,
}
#: the stirrer of the hopper and the servo paddle of the mixer (wall handles)
STRESSED = {"hopper": 2, "mixer": 3}


def outputs(s: Solver) -> dict[str, np.ndarray]:
    """Every output of a solver: per-particle arrays by id, contacts, lost particles, the meshes'
    forces and servo states, and the entries of its checkpoint."""
    out = {
        "positions": s.positions,
        "velocities": s.velocities,
        "omegas": s.omegas,
        "forces": s.forces,
        "torques": s.torques,
        "ids": s.ids,
        "energy": np.array(s.kinetic_energy()),
    }
    for key, value in zip(("i", "j", "overlap", "normal_force"), s.contacts()):
        out[f"contacts_{key}"] = value
    counts, speed = s.take_lost()
    out["lost"] = np.array([s.lost, sum(counts.values()), speed or 0.0])
    for wall, kind in s.walls().items():
        if kind == "mesh":
            out[f"mesh{wall}_triangles"] = s.mesh_triangles(wall)
            try:
                out[f"mesh{wall}_force"] = np.concatenate(s.mesh_force(wall))
            except ConfigError:  # not a stress or servo mesh
                pass
    out.update({f"state_{k}": v for k, v in s.get_state().items()})
    return out


def reference(case: str) -> dict[str, np.ndarray]:
    with np.load(DATA / f"solver_bitwise_{case}.npz") as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize("threads", THREADS)
@pytest.mark.parametrize("case", CASES)
def test_results_are_bitwise_the_reference(case, threads):
    s = CASES[case](threads)
    got = outputs(s)
    ref = {k.split("/", 1)[1]: v for k, v in reference(case).items() if k.startswith(f"{threads}/")}
    assert sorted(got) == sorted(ref)
    for key, value in ref.items():
        np.testing.assert_array_equal(got[key], value, err_msg=f"{case}, {threads} threads: {key}")
    # the scenario exercises what it is meant to: contacts, rolling springs, lost particles, meshes
    assert len(got["contacts_i"]) >= 5
    assert s.rebuilds > 2
    hs = got["state_core_nb_h"].reshape(len(got["state_core_nb_j"]), -1)
    if case in ("settle", "hopper"):
        assert np.abs(hs[:, -3:]).max() > 0  # the rolling spring torques
    if case == "shear":  # contacts with and without friction
        shear = np.linalg.norm(hs[:, :3], axis=1)
        assert (shear[hs[:, 3] != 0] == 0).any() and (shear > 0).any()
    if case == "hopper":
        assert got["lost"][0] > 0
    if case in STRESSED:
        assert np.abs(got[f"mesh{STRESSED[case]}_force"]).max() > 0


@pytest.mark.parametrize("threads", THREADS)
def test_one_type_gives_what_two_types_of_one_material_give(threads):
    """With one type the batched pair loop takes the pair values once, with more it takes each
    pair's (which the shear reference checks): the same numbers, so the same results."""
    one = outputs(shear(threads, SHEAR_MATERIALS[:1]))
    two = outputs(shear(threads, SHEAR_MATERIALS[:1] * 2))
    assert len(one["contacts_i"]) >= 20
    for key in (
        "positions",
        "velocities",
        "omegas",
        "forces",
        "torques",
        "contacts_normal_force",
        "state_core_nb_h",
    ):
        np.testing.assert_array_equal(one[key], two[key], err_msg=key)


if __name__ == "__main__":  # write the references anew from the build in use
    for name, run in CASES.items():
        arrays = {f"{t}/{k}": v for t in THREADS for k, v in outputs(run(t)).items()}
        np.savez_compressed(DATA / f"solver_bitwise_{name}.npz", **arrays)
        print(name, {t: run(t).n for t in THREADS}, file=sys.stderr)
