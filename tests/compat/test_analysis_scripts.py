"""PyGran 1.x analysis scripts, as users wrote them from the manual (chapters 5 and 6) and the
original package's own tests, run unchanged (``from PyGran import analysis``) on the real
LIGGGHTS hopper run.

Every expected number is computed here independently of PyGran: particle counts from the
dump headers, neighbours and overlaps from the full distance matrix, the RDF from a
histogram of all distances, the coarse-graining checked pair by pair.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from PyGran import analysis
from pygran_core.errors import ConfigError, PyGranError

COUNTS = [0] + [571] * 20 + [568, 559, 551, 538, 519, 506, 486, 466, 445, 423]
COLUMNS = ["id", "type", "x", "y", "z", "radius", "vx", "vy", "vz", "fx", "fy", "fz"]


def read_dump(path):
    """(timestep, atom count, columns, rows) of a one-frame LIGGGHTS dump, parsed by hand."""
    lines = path.read_text().splitlines()
    timestep, natoms = int(lines[1]), int(lines[3])
    columns = lines[8].split()[2:]
    rows = np.array([[float(v) for v in line.split()] for line in lines[9 : 9 + natoms]])
    return timestep, natoms, columns, rows.reshape(natoms, len(columns))


def contacts(rows):
    """Touching pairs (i < j) and their overlaps from the full distance matrix."""
    xyz, radius = rows[:, 2:5], rows[:, 5]
    distance = np.sqrt(((xyz[:, None, :] - xyz[None, :, :]) ** 2).sum(axis=-1))
    reach = radius[:, None] + radius[None, :]
    i, j = np.nonzero(np.triu(distance <= reach * (1 + 1e-9), k=1))
    return i, j, (reach - distance)[i, j]


def test_looping_over_a_trajectory_yields_each_following_frame_in_order(hopper):
    # Manual chapter 5 and the original: frame 0 is read on construction; "for frame in
    # System(...)" rewinds, then moves to each following frame and yields its number.
    expected = [read_dump(hopper / f"particles{1000 * k}.dump") for k in range(31)]
    assert [n for _, n, _, _ in expected] == COUNTS

    Gran = analysis.System(Particles=str(hopper / "particles*.dump"), Mesh=str(hopper / "mesh*.vtk"))
    assert Gran.frame == 0 and len(Gran) == 31  # frame 0 is read on construction
    assert Gran.Particles.natoms == COUNTS[0]
    frames, steps, counts, cells = [], [], [], []
    for frame in Gran:
        frames.append(frame)
        steps.append(Gran.Particles.timestep)
        counts.append(Gran.Particles.natoms)
        cells.append(Gran.Mesh.nCells())
    assert frames == list(range(1, 31))
    assert steps == [t for t, _, _, _ in expected][1:] == list(range(1000, 31000, 1000))
    assert counts == COUNTS[1:] and cells == [320] * 30
    assert Gran.frame == 0  # rewound, ready for the next loop
    assert [Gran.Particles.natoms for _ in Gran] == COUNTS[1:]


def test_original_system_test_skip_next_and_last_frame(hopper):
    # The original package's test_system.py, with len(System) the number of frames.
    sys = analysis.System(Particles=str(hopper / "particles*.dump"))
    assert sys.frame == 0
    sys.skip()  # skip any empty frames
    assert sys.frame == 1 and sys.Particles.natoms == 571
    sys.next()
    assert sys.frame == 2
    sys.goto(-1)  # go to last frame
    assert sys.frame == 30 and sys.Particles.timestep == 30000 and len(sys) == 31
    with pytest.raises(StopIteration):
        sys.next()


def test_micro_units_rdf_and_coordination_on_the_last_frame(hopper):
    # The original package's test_particles_struct.py, with the numbers checked.
    _, natoms, _, rows = read_dump(hopper / "particles30000.dump")
    sys = analysis.System(Particles=str(hopper / "particles*.dump"), units="si")
    sys.goto(-1)
    Particles = sys.Particles
    assert sys.units() == "si" and Particles.units == "si"
    sys.units("micro")  # converts the current frame in place: Particles sees it
    assert sys.units == "micro" and Particles.units == "micro"
    np.testing.assert_allclose(Particles.x, rows[:, 2] * 1e6, rtol=1e-12)
    np.testing.assert_allclose(Particles.radius, 50.0, rtol=1e-12)  # 5e-5 m
    np.testing.assert_allclose(Particles.vz, rows[:, 8], rtol=1e-12)  # m/s == um/us
    np.testing.assert_allclose(Particles.fz, rows[:, 11] * 1e9, rtol=1e-12)  # N -> pg um/us^2
    sys.goto(5)
    np.testing.assert_allclose(sys.Particles.radius, 50.0, rtol=1e-12)  # later frames too
    sys.goto(-1)

    g, r, refs = sys.Particles.computeRDF()
    assert r.max() > 4.0  # the original test's check, in micrometres
    xyz = rows[:, 2:5] * 1e6
    low, high = xyz.min(axis=0), xyz.max(axis=0)
    r_max = (high - low).min() / 4
    inside = np.flatnonzero(((xyz >= low + r_max) & (xyz <= high - r_max)).all(axis=1))
    np.testing.assert_array_equal(refs, inside)
    edges = np.linspace(0, r_max, 101)
    distance = np.sqrt(((xyz[inside, None, :] - xyz[None, :, :]) ** 2).sum(axis=-1))
    hist = np.histogram(distance[distance > 0], bins=edges)[0]
    density = (natoms - 1) / np.prod(high - low)
    expected = hist / (len(inside) * density * 4 / 3 * np.pi * np.diff(edges**3))
    np.testing.assert_allclose(g, expected, rtol=1e-9)
    np.testing.assert_allclose(r, (edges[1:] + edges[:-1]) / 2, rtol=1e-12)

    neigh = analysis.equilibrium.Neighbors(sys.Particles)
    i, j, depth = contacts(rows)
    coon = np.bincount(np.concatenate((i, j)), minlength=natoms)
    np.testing.assert_array_equal(neigh.coon, coon)
    np.testing.assert_array_equal(neigh.coon(), coon)  # the original's method call
    assert neigh.coon.sum() == 2 * len(i) and round(neigh.coon.mean(), 3) == round(coon.mean(), 3)

    overlapping = depth > 1e-9 * 1e-4
    found = {(i_, j_): d for d, i_, j_ in neigh.overlaps}
    assert set(found) == set(zip(i[overlapping].tolist(), j[overlapping].tolist()))
    for (a, b), d in zip(zip(i[overlapping], j[overlapping]), depth[overlapping]):
        assert found[(a, b)] == pytest.approx(d * 1e6, rel=1e-6)
    for contact in neigh.overlaps:  # the original's way: int() on the index columns
        first = sys.Particles[int(contact[1])]
        assert first.natoms == 1 and first.id[0] == rows[contact.i, 0]
    assert sys.Particles[neigh.overlaps.i].natoms == overlapping.sum()

    chains = neigh.forceChain()  # Hertzian contact forces; chains of above-mean contacts
    d, a, b = depth[overlapping] * 1e6, i[overlapping], j[overlapping]
    hertz = np.sqrt(50.0 * 50.0 / 100.0) * d**1.5
    assert chains.contacts.tolist() == np.column_stack((a, b)).tolist()
    np.testing.assert_allclose(chains.forces, hertz, rtol=1e-6)
    assert chains.strong.sum() == np.count_nonzero(hertz > hertz.mean())
    assert all(len(chain) >= 3 for chain in chains.chains)


def test_slicing_iteration_and_operators_of_the_manual(hopper):
    # Manual chapters 5 and 6.3, and the original package's test_particles_basic.py.
    _, natoms, columns, rows = read_dump(hopper / "particles30000.dump")
    Sys = analysis.System(Particles=str(hopper / "particles*.dump"))
    Sys.goto(-1)
    assert Sys.frame == 30
    Particles = Sys.Particles.copy()

    assert columns == COLUMNS and list(Particles.keys) == COLUMNS
    assert str(Particles.keys) == str(COLUMNS) and Particles.keys() == COLUMNS
    assert [k for k in Particles.keys if k.startswith("v")] == ["vx", "vy", "vz"]

    nparts = 0
    for part in Particles:  # looping yields a Particles class of length 1
        nparts += len(part)
        assert isinstance(part, analysis.Particles) and part.natoms == 1
    assert nparts == len(Particles) == natoms == 423

    assert len(Particles[:10]) == 10 and len(Particles[[1, 2, 10]]) == 3
    np.testing.assert_array_equal(Particles[[1, 2, 10]].id, rows[[1, 2, 10], 0])
    np.testing.assert_array_equal(Particles[np.array([4, 0])].id, rows[[4, 0], 0])
    assert Particles[5].id[0] == rows[5, 0] and Particles[-1].id[0] == rows[-1, 0]
    Slice = Particles[:10] + Particles[-10:]
    np.testing.assert_array_equal(Slice.id, np.concatenate((rows[:10, 0], rows[-10:, 0])))
    assert len(Particles[Particles.radius <= Particles.radius.mean() * 0.25]) == 0
    quadrant = Particles[(Particles.y >= 0) & (Particles.x >= 0)]
    assert len(quadrant) == np.count_nonzero((rows[:, 3] >= 0) & (rows[:, 2] >= 0)) > 0
    h, r = 2e-3, 5e-4
    sel = (Particles.vz != 0) | ((Particles.z <= h) & (Particles.x**2 + Particles.y**2 <= r**2))
    x, y, z, vz = rows[:, 2], rows[:, 3], rows[:, 4], rows[:, 8]
    assert len(Particles[sel]) == np.count_nonzero((vz != 0) | ((z <= h) & (x**2 + y**2 <= r**2)))

    # attributes are read-only to the user; only the methods change them
    with pytest.raises(ValueError):
        Particles.x[0] = 1.0
    with pytest.raises(AttributeError, match="read-only"):
        Particles.x = np.zeros(natoms)

    # manual 6.2: the copy constructor, by the class's own name or SubSystem
    for CopySS in (analysis.Particles(Particles=Particles), analysis.SubSystem(SubSystem=Particles)):
        assert len(CopySS) == natoms and list(CopySS.keys) == COLUMNS
        np.testing.assert_array_equal(CopySS.vx, rows[:, 6])
    NewSS = analysis.Particles(**{name: rows[:, k] for k, name in enumerate(COLUMNS)})
    assert NewSS.natoms == natoms and NewSS.units == "si"

    moved = Particles.copy()
    moved.translate(value=(-moved.x.min(), -moved.y.min(), -moved.z.min()), attr=("x", "y", "z"))
    np.testing.assert_allclose([moved.x.min(), moved.y.min(), moved.z.min()], 0, atol=0)
    np.testing.assert_allclose(moved.z, rows[:, 4] - rows[:, 4].min(), rtol=1e-12)
    np.testing.assert_array_equal(Particles.z, rows[:, 4])  # the copy moved, not the original
    moved.translate((1e-3,), ("y",))
    np.testing.assert_allclose(moved.y, rows[:, 3] - rows[:, 3].min() + 1e-3, rtol=1e-12)
    with pytest.raises(ConfigError, match="one per attribute"):
        moved.translate((1.0, 2.0), ("x", "y", "z"))

    A = Particles[:10].copy()
    A += Particles[10:20]
    np.testing.assert_array_equal(A.id, rows[:20, 0])
    with pytest.raises(ConfigError, match="lacks"):
        A += analysis.Particles(x=[0.0], y=[0.0], z=[0.0])

    Pi, Pj, Pk = Particles[0:4], Particles[4:7], Particles[7:9]
    mixed = Pi + Pj * Pk  # n_i + n_j n_k particles (manual 6.3)
    assert mixed.natoms == 4 + 3 * 2
    product = np.sign(np.outer(rows[4:7, 4], rows[7:9, 4])) * np.sqrt(
        np.abs(np.outer(rows[4:7, 4], rows[7:9, 4]))
    )
    np.testing.assert_allclose(mixed.z, np.concatenate((rows[0:4, 4], product.ravel())), rtol=1e-12)

    for bad in (1000, np.array([0.5]), [True, False]):
        with pytest.raises((PyGranError, TypeError)):
            Particles[bad]


def test_write_and_read_back(hopper, tmp_path):
    _, _, _, rows = read_dump(hopper / "particles20000.dump")
    Sys = analysis.System(Particles=str(hopper / "particles*.dump"))
    Sys.goto(20)
    Sys.Particles.write(str(tmp_path / "frame.dump"))
    back = analysis.System(Particles=str(tmp_path / "frame.dump")).Particles
    assert back.natoms == 571 and back.timestep == 20000 and list(back.keys) == COLUMNS
    for k, name in enumerate(COLUMNS):
        np.testing.assert_allclose(getattr(back, name), rows[:, k], rtol=1e-12, atol=0)


COARSE_GRAINED = """
from PyGran import analysis

class CoarseParticles(analysis.Particles):
    def __init__(self, **args):
        super().__init__(**args)

        if 'scale' in args and 'percent' in args:
            self.scale(args['scale'], ('radius',))
            CG = analysis.equilibrium.Neighbors(self).filter(percent=args['percent'])

            self.__init__(CoarseParticles=CG)
"""


def test_coarse_particles_subclass_of_the_manual(hopper, tmp_path, monkeypatch):
    # Manual 6.3, "Custom SubSystems": the listing, with module= naming the user's module file.
    (tmp_path / "coarseGrained.py").write_text(textwrap.dedent(COARSE_GRAINED))
    monkeypatch.chdir(tmp_path)
    Traj = analysis.System(
        CoarseParticles=str(hopper / "particles*.dump"), scale=3, percent=10.0, module="coarseGrained"
    )
    Traj.goto(-1)
    CG = Traj.CoarseParticles
    assert type(CG).__name__ == "CoarseParticles" and isinstance(CG, analysis.Particles)
    Traj.CoarseParticles.write("CG.dump")

    _, _, _, rows = read_dump(hopper / "particles30000.dump")
    rows[:, 5] *= 3
    xyz, radius = rows[:, 2:5], rows[:, 5]
    distance = np.sqrt(((xyz[:, None, :] - xyz[None, :, :]) ** 2).sum(axis=-1))
    conflict = (
        radius[:, None] + radius[None, :] - distance > 0.10 * np.minimum.outer(radius, radius)
    ) & ~np.eye(len(rows), dtype=bool)
    kept = np.isin(rows[:, 0], CG.id)
    assert 0 < kept.sum() < 423 and CG.natoms == kept.sum()
    assert not conflict[np.ix_(kept, kept)].any()  # no kept pair overlaps by more than 10 %
    assert conflict[np.ix_(~kept, kept)].any(axis=1).all()  # each dropped particle had to go
    np.testing.assert_allclose(CG.radius, 3 * 5e-5, rtol=1e-12)
    written = analysis.System(Particles=str(tmp_path / "CG.dump")).Particles
    np.testing.assert_array_equal(np.sort(written.id), np.sort(CG.id))


def test_mistakes_are_named():
    with pytest.raises(ConfigError, match="Unknown unit system 'imperial'"):
        analysis.System(Particles=analysis.Particles(x=[0.0], y=[0.0], z=[0.0])).units("imperial")
    particles = analysis.Particles(x=[0.0, 1.0], y=[0.0, 0.0], z=[0.0, 0.0], radius=[0.6, 0.6])
    with pytest.raises(ConfigError, match="percent must be >= 0"):
        analysis.equilibrium.Neighbors(particles).filter(-5)
    with pytest.raises(ConfigError, match="needs a Particles object"):
        analysis.equilibrium.Neighbors(particles.x)
    with pytest.raises(AttributeError, match="Did you mean 'radius'"):
        _ = particles.radii
    with pytest.raises(TypeError):
        particles.translate()


def packing(types_of):
    """A simple cubic packing of touching spheres (radius 1) on 4 x 4 x 4 sites, typed per site."""
    sites = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = 2.0 * sites + 1.0
    return analysis.Particles(
        id=np.arange(1, 65),
        type=types_of(sites),
        x=centres[:, 0],
        y=centres[:, 1],
        z=centres[:, 2],
        radius=np.ones(64),
    )


@pytest.mark.parametrize(
    ("name", "types_of", "intensity"),
    [
        ("segregated", lambda s: np.where(s[:, 0] < 2, 1, 2), 1.0),  # two halves: pure 4-pixel voxels
        ("mixed", lambda s: 1 + s.sum(axis=1) % 2, 0.0),  # alternating: every voxel half and half
    ],
)
def test_imaging_a_mixture_slice_by_slice(tmp_path, name, types_of, intensity):
    # The original imaging workflow: slice each species into images, then measure segregation.
    from PyGran.analysis import imaging

    Particles = packing(types_of)
    resol = 0.2  # length per pixel: 10 pixels per diameter, one image per pixel of depth
    for k in range(40):
        for species in (1, 2):
            imaging.slice(
                Particles[Particles.type == species],
                k * resol,
                (k + 1) * resol,
                "z",
                resol,
                size=(40, 40),
                output=str(tmp_path / f"{name}{species}_{k}.png"),
                origin=(0, 0, 0),
            )
    images = [str(tmp_path / f"{name}1_*.png"), str(tmp_path / f"{name}2_*.png")]
    assert imaging.readImg(images[0]).shape == (40, 40, 40)
    mean, var, index = imaging.intensitySegregation(images, 20)  # voxels of 2 x 2 x 2 sites
    assert mean == [0.5, 0.5] and index == pytest.approx(intensity, abs=1e-12)
    assert Particles.computeIntensitySegregation(resol=4.0) == pytest.approx(intensity, abs=1e-12)
    if name == "segregated":
        r, R = imaging.scaleSegregation(images, 10, 500, resol, maxDist=4, seed=1)
        assert r.tolist() == pytest.approx([0, 2, 4, 6]) and R[0] == 1 and R[1] > 0.3 and R[3] < 0
        r_fft, R_fft = imaging.scaleSegregation_fft(images, 10, resol, Npts=10)
        assert R_fft[0] == pytest.approx(1) and R_fft[-1] == pytest.approx(-1)


def test_lacey_index_over_a_mixing_trajectory(tmp_path):
    # Lacey's index frame by frame: a bed written segregated, then re-typed at random.
    rng = np.random.default_rng(7)
    sites = np.stack(np.meshgrid(*[np.arange(12)] * 3, indexing="ij"), -1).reshape(-1, 3)
    segregated = np.where(sites[:, 2] < 6, 1, 2)
    for k, types in enumerate([segregated, rng.permutation(segregated), rng.permutation(segregated)]):
        bed = analysis.Particles(
            id=np.arange(1, len(sites) + 1),
            type=types,
            x=sites[:, 0] + 0.5,
            y=sites[:, 1] + 0.5,
            z=sites[:, 2] + 0.5,
            radius=np.full(len(sites), 0.5),
            timestep=1000 * k,
        )
        bed.write(str(tmp_path / f"bed{1000 * k}.dump"))
    Mix = analysis.System(Particles=str(tmp_path / "bed*.dump"))
    index = [analysis.mixing.lacey(Mix.Particles, resol=3.0)]  # frame 0, read on construction
    index += [analysis.mixing.lacey(Mix.Particles, resol=3.0) for ts in Mix]
    assert index[0] == 0.0  # every 3 x 3 x 3 cell is pure
    assert index[1] == pytest.approx(1, abs=0.05) and index[2] == pytest.approx(1, abs=0.05)
