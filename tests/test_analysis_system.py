"""System: construction, frame cursor, user subclasses (module=), units; hopper acceptance."""

import sys
import textwrap

import numpy as np
import pytest

from pygran_core import analysis
from pygran_core.analysis import Mesh, Particles, System, equilibrium
from pygran_core.errors import ConfigError, ReadError
from pygran_core.io import Frame, open_writer

COUNTS = [3, 5, 0, 2]  # particles per frame of the synthetic trajectory


def frame(k, n):
    rng = np.random.default_rng(k)
    arrays = {
        "id": np.arange(1, n + 1),
        "type": np.ones(n, dtype=int),
        **{c: rng.random(n) for c in ("x", "y", "z")},
        "radius": np.full(n, 0.01),
        "vx": np.full(n, 0.5),
    }
    return Frame(arrays, timestep=100 * k, box=np.array([[0, 1.0]] * 3), boundary=("ff", "ff", "ff"))


@pytest.fixture
def traj(tmp_path):
    """A trajectory of one file per frame (traj0.dump ... traj3.dump) with N = 3, 5, 0, 2."""
    for k, n in enumerate(COUNTS):
        with open_writer(tmp_path / f"traj{k * 100}.dump") as writer:
            writer.write_frame(frame(k, n))
    return tmp_path


def test_frames_counts_and_cursor(traj):
    system = System(Particles=str(traj / "traj*.dump"))
    assert len(system) == 4 and system.frame == 0 and system.names == ["Particles"]
    assert len(system.Particles) == 3 and system.Particles.timestep == 0
    assert system.next() == 1 and len(system.Particles) == 5
    assert system.goto(-1) == 3 and system.Particles.timestep == 300
    with pytest.raises(StopIteration):
        system.next()
    assert system.goto(2) == 2 and len(system.Particles) == 0
    assert system.Particles.keys()[:2] == ["id", "type"] and system.Particles.keys[:2] == ("id", "type")
    assert system.rewind() == 0 and system.Particles.timestep == 0
    np.testing.assert_array_equal(system.Particles.x, frame(0, 3).arrays["x"])


def test_iteration_rewinds_then_visits_each_following_frame_and_repeats(traj):
    system = System(Particles=str(traj / "traj*.dump"))
    system.goto(2)
    first = [(frame, system.frame, len(system.Particles)) for frame in system]
    second = [(frame, system.frame, len(system.Particles)) for frame in system]
    assert first == second == [(k, k, n) for k, n in enumerate(COUNTS)][1:]  # frame 0 read before
    assert system.frame == 0
    assert [(k, system.timestep) for k in system.frames()] == [(k, 100 * k) for k in range(4)]


def test_skip_moves_to_the_first_frame_with_particles(traj):
    system = System(Particles=str(traj / "traj*.dump"))
    assert system.skip() == 0  # frame 0 has 3 particles
    system.goto(2)  # empty
    assert system.skip() == 3 and len(system.Particles) == 2


def test_sources_list_tuple_and_object(traj):
    files = [traj / f"traj{k * 100}.dump" for k in range(4)]
    by_list = System(Particles=[str(f) for f in files])
    by_tuple = System(Particles=(str(traj / "traj*.dump"), {"format": "dump"}))
    assert len(by_list) == len(by_tuple) == 4
    built = Particles(x=[0.0], y=[0.0], z=[0.0], radius=[1.0])
    alone = System(Particles=built)
    assert len(alone) == 1 and alone.Particles is built and list(alone) == [] and list(alone.frames()) == [0]
    holder = _module_with("Fixed")
    fixed = holder.Fixed(Particles=built)
    mixed = System(Particles=str(traj / "traj*.dump"), Fixed=fixed, module=holder)
    assert len(mixed) == 4 and mixed.goto(3) == 3 and mixed.Fixed is fixed
    with pytest.raises(ConfigError, match="Fixed= was given a Particles"):
        System(Fixed=built, module=holder)


def _module_with(name):
    import types

    module = types.ModuleType("holder")
    setattr(module, name, type(name, (Particles,), {}))
    return module


def test_bad_input_is_named(traj):
    with pytest.raises(ReadError, match="No file matches .*nothing\\*.dump"):
        System(Particles=str(traj / "nothing*.dump"))
    with pytest.raises(ReadError, match="File not found: .*missing.dump"):
        System(Particles=str(traj / "missing.dump"))
    with pytest.raises(ConfigError, match="unknown SubSystem class 'Particle'. Did you mean 'Particles'"):
        System(Particle=str(traj / "traj*.dump"))
    with pytest.raises(ConfigError, match="needs at least one SubSystem"):
        System(units="si")
    with pytest.raises(ConfigError, match="Unknown unit system 'imperial'"):
        System(Particles=str(traj / "traj*.dump"), units="imperial")
    with pytest.raises(ConfigError, match="takes a file name or glob"):
        System(Particles=42)
    system = System(Particles=str(traj / "traj*.dump"))
    with pytest.raises(IndexError, match="Frame 4 is out of range: the system has 4 frames"):
        system.goto(4)
    with pytest.raises(IndexError, match="Frame -5 is out of range"):
        system.goto(-5)
    with pytest.raises(AttributeError, match="no attribute 'Partciles'. Did you mean 'Particles'"):
        _ = system.Partciles
    with pytest.raises(AttributeError, match="no attribute 'vz'"):
        _ = system.Particles.vz


def test_mismatched_frame_counts_are_rejected(traj):
    with open_writer(traj / "short.dump") as writer:
        writer.write_frame(frame(0, 2))
        writer.write_frame(frame(1, 2))
    with pytest.raises(ConfigError, match="different numbers of frames"):
        System(Particles=str(traj / "traj*.dump"), Copy=str(traj / "short.dump"), module=_module_with("Copy"))


def test_units_convert_on_read_and_round_trip_exactly(traj):
    si = System(Particles=str(traj / "traj*.dump"))
    micro = System(Particles=str(traj / "traj*.dump"), units="micro")
    assert micro.units == "micro" and micro.Particles.units == "micro"
    np.testing.assert_allclose(micro.Particles.x, si.Particles.x * 1e6, rtol=1e-15)
    np.testing.assert_allclose(micro.Particles.vx, si.Particles.vx, rtol=1e-15)  # m/s == um/us
    np.testing.assert_array_equal(micro.Particles.id, si.Particles.id)
    np.testing.assert_array_equal(micro.Particles.convert("si").x, si.Particles.x)


USER_MODULE = '''
from pygran_core import analysis

class Grains(analysis.Particles):
    """Doubles the radius when asked to; counts its constructions."""

    def __init__(self, **args):
        grow = args.pop("grow", 1.0)
        super().__init__(**args)
        if grow != 1.0:
            self.scale(grow, ("radius",))
'''


def test_module_by_path_name_or_object_without_touching_sys_path(traj, monkeypatch):
    source = traj / "usergrains.py"
    source.write_text(textwrap.dedent(USER_MODULE))
    path_before, modules_before = list(sys.path), set(sys.modules)
    by_path = System(Grains=str(traj / "traj*.dump"), grow=2.0, module=str(source))
    assert type(by_path.Grains).__name__ == "Grains" and isinstance(by_path.Grains, Particles)
    np.testing.assert_allclose(by_path.Grains.radius, 0.02)
    monkeypatch.chdir(traj)
    by_name = System(Grains="traj*.dump", module="usergrains")
    np.testing.assert_allclose(by_name.Grains.radius, 0.01)
    assert sys.path == path_before and set(sys.modules) == modules_before
    assert type(by_name.Grains[0:1]).__name__ == "Grains"  # slicing keeps the user class
    with pytest.raises(ConfigError, match="module='nosuchmodule': no such module"):
        System(Grains="traj*.dump", module="nosuchmodule")
    with pytest.raises(ConfigError, match="unknown SubSystem class 'Grains'.*needs module="):
        System(Grains="traj*.dump")


# -- acceptance on the real LIGGGHTS hopper run ----------------------------------------------


def hopper_counts():
    return [0] + [571] * 20 + [568, 559, 551, 538, 519, 506, 486, 466, 445, 423]


def test_hopper_frames_and_particle_counts(hopper):
    system = System(Particles=str(hopper / "particles*.dump"), Mesh=str(hopper / "mesh*.vtk"))
    assert len(system) == 31
    counts = [len(system.Particles) for _ in system.frames()]
    assert counts == hopper_counts() and max(counts) == 571 and counts[0] == 0
    assert [system.Particles.timestep for _ in system.frames()] == list(range(0, 31000, 1000))
    assert system.goto(-1) == 30 and system.Particles.timestep == 30000 and len(system.Particles) == 423
    assert isinstance(system.Mesh, Mesh) and system.Mesh.nCells() == 320 and system.Mesh.nPoints() == 960
    np.testing.assert_array_equal(system.Mesh.cells.shape, (320, 3))
    assert system.Mesh.computeAreas().min() > 0
    np.testing.assert_allclose(system.Particles.radius, 5e-5)


def test_hopper_coordination_and_rdf(hopper):
    system = System(Particles=str(hopper / "particles*.dump"))
    system.goto(1)  # the freshly inserted packing
    particles = system.Particles
    neighbors = equilibrium.Neighbors(particles)
    coon = neighbors.coon
    assert coon.shape == (571,) and coon.sum() == 2 * len(neighbors.pairs)
    assert (neighbors.distances <= 2 * 5e-5 * (1 + 1e-9)).all()
    wide = equilibrium.Neighbors(particles, cutoff=3e-4)
    assert wide.coon.mean() > coon.mean()
    rdf = particles.computeRDF()
    assert np.isfinite(rdf.g).all() and rdf.g.max() > 0 and rdf.references.size > 0
    system.goto(-1)
    assert equilibrium.Neighbors(system.Particles).coon.shape == (423,)
    assert system.Particles.computeRDF().g.size == 100


def test_analysis_exports():
    assert set(analysis.__all__) == {
        "System",
        "SubSystem",
        "Particles",
        "Mesh",
        "equilibrium",
        "dynamics",
        "imaging",
        "mixing",
        "plot",
        "drum",
        "Contacts",
        "coarse_grain",
        "CoarseGrain",
        "Fields",
        "Grid1D",
        "Grid2D",
        "Grid3D",
        "GridCylindrical",
    }


def _emptied(path):
    """Every dataset of an H5MD file cut to no frames: the file a run killed between laying it
    out and writing its first frame leaves."""
    import h5py

    with h5py.File(path, "r+") as f:
        datasets = []
        f.visititems(lambda _, item: datasets.append(item) if isinstance(item, h5py.Dataset) else None)
        for d in datasets:
            if d.maxshape and d.maxshape[0] is None:
                d.resize(0, axis=0)


def test_a_trajectory_without_frames_is_a_read_error_and_contacts_without_frames_are_none(tmp_path):
    path = tmp_path / "traj.h5"
    with open_writer(path, contacts=True) as writer:
        for k in range(3):
            writer.write_frame(frame(k, 4))
    with System(Particles=str(path)) as system:  # contacts laid out, none written: no Contacts
        assert len(system) == 3 and [len(system.Particles) for _ in system.frames()] == [4, 4, 4]
        assert not hasattr(system, "Contacts")
    _emptied(path)
    with pytest.raises(ReadError, match=r"traj\.h5'? holds no frames"):
        System(Particles=str(path))
