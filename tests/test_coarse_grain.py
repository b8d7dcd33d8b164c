"""Coarse-graining (pygran_core.analysis.coarse_grain): closed forms on both the compiled and the
numpy path, the System front end, errors, plots and VTK output, and a settled bed simulated on
the native engine."""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib
import numpy as np
import pytest

from pygran_core import analysis
from pygran_core.analysis import CoarseGrain, Grid1D, Grid2D, Grid3D, GridCylindrical, Particles, System
from pygran_core.analysis import coarse_grain as cg
from pygran_core.analysis.contacts import Contacts
from pygran_core.errors import ConfigError, SelectionError
from pygran_core.io import Frame, open_writer
from pygran_core.testing.solvers import kernel_path

matplotlib.use("Agg")

KERNELS = ("gaussian", "lucy", "heaviside")
BOX = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 2.0]])
WIDTH = 0.08


@pytest.fixture(params=["compiled", "numpy"])
def path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    return kernel_path(request.param, cg, monkeypatch)


def bed(n: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.random((n, 3)) * BOX[:, 1], rng.uniform(0.5, 1.5, n), rng.normal(size=(n, 3))


def covering() -> list[cg.Grid]:
    """Grids that cover the bed and every kernel's support."""
    pad = 0.5
    x, y, z = ((lo - pad, hi + pad) for lo, hi in BOX)
    return [
        Grid1D(axis="z", bins=30, range=z, area=1.0),
        Grid2D(axes=("z", "x"), bins=(30, 20), range=(z, x), depth=1.0),
        Grid3D(bins=(20, 20, 30), range=(x, y, z)),
        GridCylindrical(axis="z", bins=(20, 30), range=((0.0, 1.5), z), centre=(0.5, 0.5)),
    ]


@pytest.mark.parametrize("kernel", KERNELS)
def test_the_grid_holds_the_particles_mass(path: str, kernel: str) -> None:
    positions, mass, velocity = bed()
    for grid in covering():
        fields = cg.coarse_grain(grid, positions, mass, velocity, kernel=kernel, width=WIDTH)
        assert fields.mass == pytest.approx(mass.sum(), rel=1e-12, abs=0), type(grid).__name__
        momentum = (fields.momentum * fields.cell_volume[..., None]).reshape(-1, 3).sum(axis=0)
        if not isinstance(grid, GridCylindrical):
            np.testing.assert_allclose(momentum, mass @ velocity, rtol=1e-12, atol=1e-12 * np.abs(mass).sum())


@pytest.mark.parametrize("kernel", KERNELS)
def test_contact_stress_integrates_to_the_sum_of_f_times_b(path: str, kernel: str) -> None:
    positions, mass, _ = bed()
    rng = np.random.default_rng(1)
    first = rng.integers(0, len(positions), 300)
    branch = rng.normal(size=(300, 3)) * 0.05
    branch[::4, 0] = 0.0  # lines parallel to a grid plane
    force = rng.normal(size=(300, 3))
    expected = force.T @ branch
    for grid in covering()[:3]:
        fields = cg.coarse_grain(
            grid, positions, mass, None, (positions[first], branch, force), kernel=kernel, width=WIDTH
        )
        total = (fields.contact_stress * fields.cell_volume[..., None, None]).reshape(-1, 3, 3).sum(axis=0)
        np.testing.assert_allclose(total, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("kernel", KERNELS)
def test_a_chain_under_a_force_has_the_stress_force_over_area(path: str, kernel: str) -> None:
    # spheres of radius r stacked along z, each pushed up by the one below with force F
    r, force, n = 0.05, 3.0, 41
    z = (2 * np.arange(n) + 1) * r
    positions = np.column_stack((np.full(n, 0.5), np.full(n, 0.5), z))
    branch = np.tile([0.0, 0.0, 2 * r], (n - 1, 1))
    forces = np.tile([0.0, 0.0, force], (n - 1, 1))
    grid = Grid1D(axis="z", bins=480, range=(-1.0, 5.0), area=0.25)
    fields = cg.coarse_grain(
        grid, positions, np.ones(n), None, (positions[1:], branch, forces), kernel=kernel, width=r
    )
    stress = fields.contact_stress[..., 2, 2]
    assert (stress * fields.cell_volume).sum() == pytest.approx((n - 1) * 2 * r * force, rel=1e-12)
    inside = (fields.coordinates[0] > z[0] + 4 * r) & (fields.coordinates[0] < z[-1] - 4 * r)
    np.testing.assert_allclose(stress[inside], force / 0.25, rtol=1e-2)
    assert np.abs(fields.contact_stress[..., :2, :]).max() == 0.0


@pytest.mark.parametrize("kernel", KERNELS)
def test_a_contact_line_spreads_the_kernel_integrated_along_it(path: str, kernel: str) -> None:
    # single lines (up to 3 widths long) on a grid with cells one width wide, against the kernel
    # summed at 5000 points along each line, weights normalised over the grid: the top hat is
    # exact (its weight is the length inside each cell's box); Gaussian and Lucy are integrated by
    # 2-point Gauss-Legendre, within 1e-3 of the largest weight (measured: up to 6e-4)
    width, h = 0.05, 0.05
    grid = Grid3D(bins=(16, 16, 16), range=((0.0, 0.8),) * 3)
    rng = np.random.default_rng(3)
    samples = (np.arange(5000) + 0.5) / 5000
    profile = cg.Kernel(kernel, width).profile
    for _ in range(8):
        start = 0.4 + rng.uniform(-h, h, 3)
        branch = rng.normal(size=3)
        branch *= rng.uniform(0.0, 3 * width) / np.linalg.norm(branch)
        fields = cg.coarse_grain(
            grid,
            start[None],
            [1.0],
            None,
            (start[None], branch[None], [[1.0, 0.0, 0.0]]),
            kernel=kernel,
            width=width,
        )
        a = int(np.argmax(np.abs(branch)))  # contact_stress[..., 0, a] = weight * b_a / cell volume
        weight = fields.contact_stress[..., 0, a] * fields.cell_volume / branch[a]
        if kernel == "heaviside":  # t where the line is inside each cell's box |x - centre| < sqrt(3) w
            c = np.sqrt(3.0) * width
            lo, hi = [], []
            for k in range(3):
                offset = start[k] - fields.coordinates[k]  # x - centre = offset - t b
                ends = np.clip(np.sort([(offset - c) / branch[k], (offset + c) / branch[k]], axis=0), 0, 1)
                shape = [1, 1, 1]
                shape[k] = -1
                lo.append(ends[0].reshape(shape))
                hi.append(ends[1].reshape(shape))
            exact = np.maximum(
                np.minimum(np.minimum(*hi[:2]), hi[2]) - np.maximum(np.maximum(*lo[:2]), lo[2]), 0
            )
            np.testing.assert_allclose(weight, exact / exact.sum(), rtol=1e-12, atol=1e-15)
            continue
        g = [
            profile(fields.coordinates[k][None, :] - (start[k] - samples[:, None] * branch[k]))
            for k in range(3)
        ]
        reference = ((g[0][:, :, None] * g[1][:, None, :]).reshape(len(samples), -1).T @ g[2]).reshape(
            weight.shape
        )
        reference /= reference.sum()
        assert np.abs(weight - reference).max() < 1e-3 * reference.max()


@pytest.mark.parametrize("kernel", KERNELS)
def test_a_uniformly_moving_bed_has_no_kinetic_stress(path: str, kernel: str) -> None:
    positions, mass, _ = bed()
    velocity = np.tile([0.3, -2.0, 1.1], (len(mass), 1))
    rng = np.random.default_rng(2)
    first = rng.integers(0, len(mass), 200)
    contacts = (positions[first], rng.normal(size=(200, 3)) * 0.03, rng.normal(size=(200, 3)))
    for grid in covering()[:3]:
        moving = cg.coarse_grain(grid, positions, mass, velocity, contacts, kernel=kernel, width=WIDTH)
        still = cg.coarse_grain(grid, positions, mass, 0 * velocity, contacts, kernel=kernel, width=WIDTH)
        filled = moving.density > 1e-6 * moving.density.max()
        np.testing.assert_allclose(
            moving.velocity[filled], np.broadcast_to(velocity[0], (filled.sum(), 3)), rtol=1e-12
        )
        scale = (moving.density[..., None, None] * 4.0).max()  # rho |v|^2
        assert np.abs(moving.kinetic_stress).max() < 1e-12 * scale
        assert np.abs(still.kinetic_stress).max() == 0.0
        np.testing.assert_allclose(moving.stress, still.contact_stress, atol=1e-12 * scale)


def test_gaussian_and_lucy_kernels_of_one_width_give_the_same_profile(path: str) -> None:
    # a fine lattice of particles whose masses vary smoothly along z: every kernel of standard
    # deviation w smooths the profile alike to second order in w
    x, y, z = np.meshgrid(np.arange(5) / 5, np.arange(5) / 5, np.arange(800) / 400, indexing="ij")
    positions = np.column_stack((x.ravel(), y.ravel(), z.ravel()))
    mass = 1 + 0.5 * np.sin(2 * np.pi * positions[:, 2])
    grid = Grid1D(axis="z", bins=100, range=(0.0, 2.0), area=1.0)
    box = np.array([[0, 1], [0, 1], [0, 2]])
    periodic = ("pp", "pp", "pp")
    profiles = {
        name: cg.coarse_grain(
            grid, positions, mass, kernel=name, width=0.05, box=box, boundary=periodic
        ).density
        for name in ("gaussian", "lucy")
    }
    np.testing.assert_allclose(profiles["gaussian"], profiles["lucy"], rtol=2e-3)
    # and both are the smoothed profile: 25 particles per 1/400 of height, amplitude damped by exp(-k²w²/2)
    expected = (
        25 * 400 * (1 + 0.5 * np.exp(-0.5 * (2 * np.pi * 0.05) ** 2) * np.sin(2 * np.pi * grid_z(grid)))
    )
    np.testing.assert_allclose(profiles["gaussian"], expected, rtol=2e-3)


def grid_z(grid: Grid1D) -> np.ndarray:
    lo, hi = grid.range or (0.0, 1.0)
    return lo + (np.arange(grid.bins) + 0.5) * (hi - lo) / grid.bins


def test_cylindrical_fields_of_a_uniform_swirl() -> None:
    # (numpy on both paths) particles on a fine lattice in a cylinder, turning about the axis as a rigid body
    grid = GridCylindrical(axis="z", bins=(15, 20), range=((0.0, 1.5), (-0.5, 1.5)))
    x, y, z = np.meshgrid(*(np.linspace(-0.985, 0.985, 67),) * 2, np.linspace(0.01, 0.99, 40), indexing="ij")
    inside = x**2 + y**2 < 1
    positions = np.column_stack((x[inside], y[inside], z[inside]))
    velocity = np.column_stack((-positions[:, 1], positions[:, 0], np.zeros(len(positions))))
    fields = cg.coarse_grain(
        grid, positions, np.ones(len(positions)), velocity, kernel="lucy", width=0.1, box=None
    )
    assert fields.mass == pytest.approx(len(positions), rel=1e-12)
    radius = fields.coordinates[0]
    core = (radius < 0.8)[:, None] & ((fields.coordinates[1] > 0.3) & (fields.coordinates[1] < 0.7))[None, :]
    density = len(positions) / (np.pi * 1.0)  # particles per unit volume
    np.testing.assert_allclose(fields.density[core], density, rtol=0.03)  # the lattice's texture
    swirl = np.broadcast_to(radius[:, None], fields.shape)
    # the azimuthal velocity is the rigid rotation's once the kernel's reach (0.34) is off the axis
    ring = core & (swirl > 0.4)
    np.testing.assert_allclose(fields.velocity[..., 1][ring], swirl[ring], rtol=0.03)
    assert np.abs(fields.velocity[..., 0][core]).max() < 1e-3  # no radial flow


def write_frames(path, frames: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> None:
    with open_writer(path) as writer:
        for step, (positions, radius, velocity, types) in enumerate(frames):
            arrays = {
                "id": np.arange(1, len(positions) + 1),
                "type": types,
                "x": positions[:, 0],
                "y": positions[:, 1],
                "z": positions[:, 2],
                "radius": radius,
                "vx": velocity[:, 0],
                "vy": velocity[:, 1],
                "vz": velocity[:, 2],
            }
            writer.write_frame(Frame(arrays, timestep=100 * step, box=BOX, boundary=("pp", "pp", "ff")))


def test_time_averages_and_species_over_frames_of_a_system(tmp_path, path: str) -> None:
    rng = np.random.default_rng(5)
    frames = []
    for n in (300, 250, 320):  # particles come and go
        positions = rng.random((n, 3)) * BOX[:, 1]
        frames.append((positions, np.full(n, 0.01), rng.normal(size=(n, 3)), rng.integers(1, 3, n)))
    write_frames(tmp_path / "bed.dump", frames)
    system = System(Particles=str(tmp_path / "bed.dump"))
    grid = Grid1D(axis="z", bins=20, range=(-0.5, 2.5))
    cgrain = CoarseGrain(system, grid=grid, kernel="lucy", width=0.1, density=2500.0)
    every = cgrain.compute(frames=slice(0, 3))
    each = [cgrain.compute(frames=k) for k in range(3)]
    assert system.frame == 0  # compute leaves the system where it was
    np.testing.assert_allclose(every.density, np.mean([f.density for f in each], axis=0), rtol=1e-12)
    np.testing.assert_allclose(
        every.momentum, np.mean([f.momentum for f in each], axis=0), rtol=1e-12, atol=1e-9
    )
    mass = 2500.0 * 4 / 3 * np.pi * 0.01**3
    assert every.mass == pytest.approx(mass * np.mean([len(f[0]) for f in frames]), rel=1e-12)
    one, two = (cgrain.compute(frames=[0, 2], species=s) for s in (1, 2))
    both = cgrain.compute(frames=[0, 2], species=(1, 2))
    np.testing.assert_allclose(one.density + two.density, both.density, rtol=1e-12)
    counts = sum((f[3] == 1).sum() for f in (frames[0], frames[2])) / 2
    assert one.mass == pytest.approx(mass * counts, rel=1e-12)
    assert "1 frame(s)" in repr(each[0]) and "species [1]" in repr(one)


def test_contacts_of_a_system_by_species(path: str) -> None:
    rng = np.random.default_rng(6)
    n = 200
    positions = rng.random((n, 3)) * BOX[:, 1]
    ids = np.arange(10, 10 + n)
    particles = Particles(
        id=ids, type=rng.integers(1, 3, n), x=positions[:, 0], y=positions[:, 1], z=positions[:, 2],
        radius=np.full(n, 0.02), mass=np.ones(n), vx=np.zeros(n), vy=np.zeros(n), vz=np.zeros(n),
        box=BOX, boundary=("ff", "ff", "ff"),
    )  # fmt: skip
    i, j = rng.integers(0, n, 150), rng.integers(0, n, 150)
    branch = positions[i] - positions[j]
    force = rng.normal(size=(150, 3))
    point = positions[i] - 0.4 * branch
    wall = np.arange(150) % 10 == 0  # a few contacts with a wall below the particle
    branch[wall] = [0.0, 0.0, 0.02]
    point[wall] = positions[i[wall]] - branch[wall]
    id2 = np.where(wall, -1, ids[j])
    contacts = Contacts(
        id1=ids[i], id2=id2, fx=force[:, 0], fy=force[:, 1], fz=force[:, 2], cx=point[:, 0], cy=point[:, 1],
        cz=point[:, 2], bx=branch[:, 0], by=branch[:, 1], bz=branch[:, 2],
    )  # fmt: skip
    system = System(Particles=particles, Contacts=contacts)
    grid = Grid3D(bins=(12, 12, 20), range=((-1.0, 2.0), (-1.0, 2.0), (-1.0, 3.0)))
    cgrain = CoarseGrain(system, grid=grid, kernel="gaussian", width=0.1)
    total = cgrain.compute()
    parts = [cgrain.compute(species=s) for s in (1, 2)]
    volume = total.cell_volume[..., None, None]
    expected = force.T @ branch
    total_sum = (total.contact_stress * volume).sum(axis=(0, 1, 2))
    np.testing.assert_allclose(total_sum, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    split = sum((p.contact_stress * volume).sum(axis=(0, 1, 2)) for p in parts)
    np.testing.assert_allclose(split, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    # the halves at the contact points sit on their own particles' sides, summing to the whole
    np.testing.assert_allclose(
        parts[0].contact_stress + parts[1].contact_stress,
        total.contact_stress,
        atol=0.05 * np.abs(total.contact_stress).max(),
    )


def test_mistakes_are_refused_with_the_fix() -> None:
    positions, mass, _ = bed(20)
    with pytest.raises(ConfigError, match="bins"):
        Grid1D(bins=0)
    with pytest.raises(ConfigError, match="low < high"):
        Grid2D(range=((1.0, 0.0), (0.0, 1.0)))
    with pytest.raises(ConfigError, match="axis"):
        Grid1D(axis="w")
    with pytest.raises(ConfigError, match="r0 >= 0"):
        GridCylindrical(range=((-1.0, 1.0), (0.0, 1.0)))
    with pytest.raises(ConfigError, match="width must be a positive"):
        cg.coarse_grain(Grid1D(range=(0, 1), area=1.0), positions, mass, width=0.0)
    with pytest.raises(ConfigError, match="Unknown kernel 'gausian'. Did you mean 'gaussian'"):
        cg.coarse_grain(Grid1D(range=(0, 1), area=1.0), positions, mass, kernel="gausian", width=0.1)
    with pytest.raises(ConfigError, match="less than one cell"):
        cg.coarse_grain(Grid1D(bins=1000, range=(0, 1), area=1.0), positions, mass, width=1e-4)
    with pytest.raises(ConfigError, match="no box"):
        cg.coarse_grain(Grid1D(), positions, mass, width=0.1)
    no_contacts = cg.coarse_grain(Grid1D(range=(0, 2), area=1.0), positions, mass, width=0.1)
    with pytest.raises(ConfigError, match="contact records"):
        _ = no_contacts.contact_stress
    with pytest.raises(AttributeError, match="velocities"):
        _ = no_contacts.velocity
    particles = Particles(x=positions[:, 0], y=positions[:, 1], z=positions[:, 2], mass=mass, box=BOX)
    system = System(Particles=particles)
    with pytest.raises(SelectionError, match="out of range"):
        CoarseGrain(system, grid=Grid1D(), width=0.1).compute(frames=[0, 3])
    with pytest.raises(ConfigError, match="width"):
        CoarseGrain(system, grid=Grid1D())
    with pytest.raises(ConfigError, match="grid must be"):
        CoarseGrain(system, grid="z", width=0.1)  # type: ignore[arg-type]


def test_vtk_image_data_reads_back(tmp_path) -> None:
    positions, mass, velocity = bed(100)
    grid = Grid2D(axes=("z", "x"), bins=(8, 5), range=((0.0, 2.0), (0.0, 1.0)), depth=1.0)
    fields = cg.coarse_grain(grid, positions, mass, velocity, kernel="lucy", width=0.3)
    fields.to_vtk(tmp_path / "bed.vti")
    root = ET.parse(tmp_path / "bed.vti").getroot()
    image = root.find("ImageData")
    assert root.get("type") == "ImageData" and image is not None
    assert image.get("WholeExtent") == "0 5 0 1 0 8"
    np.testing.assert_allclose([float(v) for v in image.get("Spacing", "").split()], [0.2, 1.0, 0.25])
    arrays = {a.get("Name"): a for a in root.iter("DataArray")}
    assert set(arrays) == {"density", "velocity", "momentum", "kinetic_stress"}
    assert arrays["kinetic_stress"].get("NumberOfComponents") == "9"
    density = np.array(arrays["density"].text.split(), dtype=float).reshape(8, 1, 5)  # z, y, x: x fastest
    np.testing.assert_array_equal(density[:, 0, :], fields.density)
    velocity_read = np.array(arrays["velocity"].text.split(), dtype=float).reshape(8, 1, 5, 3)
    np.testing.assert_array_equal(velocity_read[:, 0], np.nan_to_num(fields.velocity))


def test_plots_in_one_call(tmp_path) -> None:
    positions, mass, velocity = bed(100)
    profile = cg.coarse_grain(
        Grid1D(range=(0.0, 2.0), area=1.0, bins=20), positions, mass, velocity, width=0.1
    )
    ax = profile.plot("density", path=tmp_path / "profile.png")
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), profile.density)
    assert (tmp_path / "profile.png").stat().st_size > 0
    grid = Grid2D(axes=("x", "z"), bins=(5, 10), range=((0.0, 1.0), (0.0, 2.0)), depth=1.0)
    plane = cg.coarse_grain(grid, positions, mass, velocity, width=0.1)
    ax = plane.plot("velocity_z", quiver=True)
    np.testing.assert_array_equal(ax.collections[0].get_array().reshape(10, 5), plane.velocity[..., 2].T)
    with pytest.raises(ConfigError, match="Unknown quantity"):
        plane.plot("stress_zw")


@pytest.fixture(scope="module")
def settled_bed(tmp_path_factory) -> tuple[Path, str]:
    """The guide's settled-bed example, run once: its folder and what it printed."""
    cwd = tmp_path_factory.mktemp("bed")
    return cwd, run_example("coarse_grain_bed.py", cwd)


@pytest.mark.parametrize("kernel", ["lucy", "gaussian"])
def test_settled_periodic_bed_carries_its_weight(settled_bed, kernel: str) -> None:
    """400 beads settled on a floor in a periodic box (the guide's example, native engine with
    its contacts): the vertical stress at height z is the weight above it per unit area,
    g ∫_z^top rho dz, within 5 % away from the top and the bottom two diameters (measured: 3.3 %
    with Lucy), and the bed is at rest (kinetic stress below 1e-5 of the contact stress)."""
    radius = 1e-3
    system = System(Particles=str(settled_bed[0] / "out-bed" / "traj.h5"))
    system.goto(-1)
    assert len(system.Particles) == 400
    top = float((system.Particles.z + system.Particles.radius).max())
    grid = Grid1D(axis="z", bins=240, range=(-0.005, top + 0.005))
    fields = CoarseGrain(system, grid=grid, kernel=kernel, width=radius, density=2500.0).compute()
    z, dz = fields.coordinates[0], grid_z(grid)[1] - grid_z(grid)[0]
    weight = 9.81 * np.cumsum((fields.density * dz)[::-1])[::-1]  # g ∫_z^top rho dz'
    away = (z > 4 * radius) & (z < top - 4 * radius)
    assert away.sum() > 50
    np.testing.assert_allclose(fields.stress[..., 2, 2][away], weight[away], rtol=0.05)
    kinetic = np.abs(fields.kinetic_stress[..., 2, 2][away])
    assert kinetic.max() < 1e-5 * np.abs(fields.contact_stress[..., 2, 2][away]).max()
    assert analysis.CoarseGrain is CoarseGrain


def run_example(name: str, cwd) -> str:
    script = Path(__file__).resolve().parents[1] / "docs" / "examples" / name
    env = {**os.environ, "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, str(script)], cwd=cwd, env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, f"{name} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def test_hopper_example(tmp_path) -> None:
    """The hopper the example runs: the fields' mass flow through the outlet is the mass counted
    leaving (measured: 18.4 and 18.6 mg/s), and the flow is downwards on the axis."""
    printed = run_example("coarse_grain_hopper.py", tmp_path)
    line = printed.split("mass flow through the outlet: ", 1)[1].split("\n", 1)[0]
    fields, counted = (float(part.split(" mg/s")[0]) for part in line.split(", "))
    assert counted > 5  # the hopper discharges
    assert fields == pytest.approx(counted, rel=0.1)
    assert float(printed.split("near the axis above the outlet ", 1)[1].split(" m/s")[0]) > 0.01
    assert (tmp_path / "hopper-velocity.png").stat().st_size > 0
    assert ET.parse(tmp_path / "hopper.vti").getroot().get("type") == "ImageData"


def test_settled_bed_example(settled_bed) -> None:
    cwd, printed = settled_bed
    stress, weight = (float(v.split()[0]) for v in printed.rsplit("sigma_zz ", 1)[1].split(", weight above "))
    assert stress == pytest.approx(weight, rel=0.05)
    assert (cwd / "bed-stress.png").stat().st_size > 0
