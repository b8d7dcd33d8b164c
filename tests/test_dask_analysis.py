"""System.map on a Dask cluster: the same results as frame after frame here, in frame order, on
frames of different particle counts, with workers that read their own frames from the file.

The trajectory is written by PyGran's H5MD writer from seeded random particles in a periodic
box; a LocalCluster of two worker processes (one thread each) serves the whole module.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from pygran_core import analysis
from pygran_core.errors import ConfigError, SelectionError, UnsupportedFeature
from pygran_core.io import Frame, open_trajectory, open_writer
from pygran_core.testing.solvers import in_ci

try:
    import cloudpickle
    import dask
    import distributed
except ImportError:  # pragma: no cover - depends on the installation
    if in_ci():
        raise
    pytest.skip("Dask is not installed: pip install pygran-core[dask]", allow_module_level=True)
cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import a test module

RADIUS = 5e-4
COUNTS = (300, 420, 0, 360, 510, 250)  # particles per frame: one frame empty
SIDE = 1e-2


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("dask") / "traj.h5"
    rng = np.random.default_rng(7)
    box = np.array([[0.0, SIDE]] * 3)
    with open_writer(path, contacts=True) as writer:
        for k, n in enumerate(COUNTS):
            x = rng.uniform(0, SIDE, (n, 3))
            arrays = {
                "id": np.arange(1, n + 1, dtype=np.int64),
                "type": rng.integers(1, 3, n).astype(np.int64),
                "x": x[:, 0],
                "y": x[:, 1],
                "z": x[:, 2],
                "radius": np.full(n, RADIUS),
                "vx": rng.normal(0, 0.1, n),
                "vy": rng.normal(0, 0.1, n),
                "vz": rng.normal(0, 0.1, n),
            }
            clock = {"timestep": 1000 * k, "time": 1e-3 * k, "box": box, "boundary": ("pp",) * 3}
            writer.write_frame(Frame(arrays, **clock))
            touching = np.arange(0, n, 3)  # every third particle presses on a wall below it
            force = rng.normal(0, 1e-3, (len(touching), 3))
            contacts = {
                "id1": touching + 1,
                "id2": np.full(len(touching), -1),
                "fx": force[:, 0],
                "fy": force[:, 1],
                "fz": force[:, 2],
                "cx": x[touching, 0],
                "cy": x[touching, 1],
                "cz": x[touching, 2] - RADIUS,
                "bx": np.zeros(len(touching)),
                "by": np.zeros(len(touching)),
                "bz": np.full(len(touching), RADIUS),
            }
            writer.write_frame(Frame(contacts, attrs={"kind": "contacts"}, **clock))
    return path


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as dask_client,
    ):
        yield dask_client


def summary(system: analysis.System) -> dict[str, object]:
    """A user's per-frame analysis: the RDF, coordination numbers and a density profile."""
    particles = system.Particles
    out: dict[str, object] = {"frame": system.frame, "step": system.timestep, "n": len(particles)}
    if len(particles) < 2:
        return out
    out["rdf"] = particles.computeRDF(dr=RADIUS / 2, rMax=4 * RADIUS).g
    out["coon"] = analysis.equilibrium.Neighbors(particles).coon
    grid = analysis.Grid1D(axis="z", bins=10)
    fields = analysis.CoarseGrain(system, grid=grid, width=RADIUS, density=2500.0).compute()
    out["density"], out["stress"] = fields.density, fields.contact_stress  # the file's contacts too
    contacts = system.Contacts
    out["fb"] = float(np.sum(contacts["fz"] * contacts["bz"]))
    out["pid"] = os.getpid()
    return out


def serial(path: Path, frames: object = None) -> list[dict[str, object]]:
    """The reference: frame after frame in this process, on one OpenMP thread as the workers."""
    with threadpool_limits(1, user_api="openmp"), analysis.System(Particles=str(path)) as system:
        return system.map(summary, frames=frames, client="serial")


def same(a: list[dict[str, object]], b: list[dict[str, object]]) -> None:
    assert len(a) == len(b)
    for one, two in zip(a, b, strict=True):
        assert one.keys() == two.keys()
        for key in one.keys() - {"pid"}:
            np.testing.assert_array_equal(one[key], two[key], err_msg=key)


def test_map_on_two_workers_equals_the_serial_path(trajectory: Path, client: Any) -> None:
    with analysis.System(Particles=str(trajectory)) as system:
        assert system.names == ["Particles", "Contacts"]  # the file's contact records
        results = system.map(summary, client=client)
        assert system.frame == 0  # the caller's System did not move
    reference = serial(trajectory)
    same(results, reference)
    assert [r["n"] for r in results] == list(COUNTS)
    assert [r["step"] for r in results] == [1000 * k for k in range(len(COUNTS))]
    assert len({r["pid"] for r in results if "pid" in r}) == 2  # both workers took frames
    assert all(os.getpid() != r.get("pid") for r in results)
    # numbers a user checks: an ideal gas has g = 1 beyond the particles' own size, and the
    # density profile integrates to the frame's mass
    rdf = np.mean([r["rdf"] for r in results if "rdf" in r], axis=0)
    assert 0.8 < rdf[-4:].mean() < 1.2
    for r, n in zip(results, COUNTS, strict=True):
        if n:
            mass = n * 2500.0 * 4 / 3 * np.pi * RADIUS**3
            assert np.sum(r["density"]) * SIDE**3 / 10 == pytest.approx(mass, rel=1e-9)
            # and the contact stress integrates to sum f ⊗ b over the frame's contacts
            assert np.sum(r["stress"][:, 2, 2]) * SIDE**3 / 10 == pytest.approx(r["fb"], rel=1e-9)
            assert r["fb"] != 0


def test_a_selection_of_frames_in_the_order_asked(
    trajectory: Path, client: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    frames = [-1, 3, 0, 3]
    with analysis.System(Particles=str(trajectory)) as system:
        results = system.map(summary, frames=frames, client=client, progress=True)
        progress = capsys.readouterr().err.replace("\r", "\n").splitlines()[-1]
        assert progress.startswith("System.map: 100%") and "4/4" in progress
        address = client.scheduler.address  # as a real cluster is reached
        tail = system.map(lambda s: len(s.Particles), frames=slice(2, None), client=address)
    assert [r["frame"] for r in results] == [5, 3, 0, 3]
    same(results, serial(trajectory, frames))
    assert tail == list(COUNTS[2:])


def test_a_liggghts_run_with_its_walls(hopper: Path, client: Any) -> None:
    """Real LIGGGHTS output: dump frames of a discharging hopper and the VTK frames of its walls."""

    def outflow(system: analysis.System) -> tuple[int, int, float, float]:
        particles, walls = system.Particles, system.Mesh
        return (
            system.timestep,
            len(particles),
            float(particles.z.max(initial=0.0)),
            float(walls.computeAreas().sum()),
        )

    with analysis.System(Particles=str(hopper / "particles*.dump"), Mesh=str(hopper / "mesh*.vtk")) as system:
        there = system.map(outflow, client=client)
        here = system.map(outflow, client="serial")
        counts = [len(system.Particles) for _ in system.frames()]
    assert there == here
    assert [n for _, n, _, _ in there] == counts and len(there) == 31
    assert [step for step, *_ in there] == sorted(step for step, *_ in there)
    assert max(counts) > min(counts)  # particles come and go: variable N


class Beads(analysis.Particles):
    """A user's SubSystem class with a method of its own."""

    def widest(self) -> float:
        return float(self.x.max()) if len(self) else 0.0


def test_units_and_user_subsystems_travel_to_the_workers(trajectory: Path, client: Any) -> None:
    with analysis.System(Beads=str(trajectory), units="micro", module=sys.modules[__name__]) as system:
        here = system.map(lambda s: s.Beads.widest(), client="serial")
        there = system.map(lambda s: s.Beads.widest(), client=client)
    assert here == there
    assert there[2] == 0.0  # the empty frame
    assert 0.9 * SIDE * 1e6 < max(there) <= SIDE * 1e6  # micrometres, not metres


def test_each_worker_reads_at_most_two_frames_at_a_time(trajectory: Path) -> None:
    def slow(system: analysis.System) -> tuple[int, float, float]:
        start = time.monotonic()
        len(system.Particles)
        time.sleep(0.3)
        return os.getpid(), start, time.monotonic()

    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=4, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as four_threads,
    ):
        with analysis.System(Particles=str(trajectory)) as system:
            spans = system.map(slow, frames=[0, 1, 3, 4, 5, 0, 1, 3], client=four_threads)
    events = sorted([(start, 1) for _, start, _ in spans] + [(end, -1) for _, _, end in spans])
    held = np.cumsum([step for _, step in events])
    assert held.max() == 2  # four threads, but two frames at a time


def test_mistakes_are_named(trajectory: Path) -> None:
    with analysis.System(Particles=str(trajectory)) as system:
        with pytest.raises(SelectionError, match="out of range"):
            system.map(summary, frames=[6], client="serial")
        with pytest.raises(ConfigError, match="function"):
            system.map("rdf", client="serial")  # type: ignore[arg-type]
        with pytest.raises(ConfigError, match="client="):
            system.map(summary, client=3)
        with pytest.raises(ConfigError, match="workers=2 sizes the local cluster"):
            system.map(summary, client="serial", workers=2)
        with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
            with pytest.raises(ConfigError, match="no Dask scheduler answers"):
                system.map(summary, client="tcp://127.0.0.1:9")
    with analysis.System(Particles=open_trajectory(trajectory)) as system:
        with pytest.raises(UnsupportedFeature, match="file name"):
            system.map(summary, client="tcp://127.0.0.1:9")


def test_without_dask_the_error_says_what_to_install(
    trajectory: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)
    with analysis.System(Particles=str(trajectory)) as system:
        with pytest.raises(UnsupportedFeature, match=r"pip install pygran-core\[dask\]"):
            system.map(summary)
        assert len(system.map(summary, frames=[0], client="serial")) == 1  # no Dask needed here
