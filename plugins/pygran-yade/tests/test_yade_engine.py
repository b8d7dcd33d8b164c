"""The YADE engine on the real YADE: impacts against the reference contact models, the
settle scenario against the native engine, and YADE failures as EngineError."""

from __future__ import annotations

import math
import os
import signal

import numpy as np
import pytest

from pygran_core import registry, simulation
from pygran_core.errors import EngineError, UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.testing.solvers import in_ci, require_solver

MATERIAL = {
    "youngsModulus": 5e6,
    "poissonsRatio": 0.45,
    "coefficientRestitution": 0.3,
    "coefficientFriction": 0.5,
    "density": 2500.0,
    "characteristicVelocity": 0.5,
}
R, V0, DT = 1e-3, 0.5, 1e-7
#: Measured: YADE's Mindlin law gives sphere-wall contacts R* = R/2 (the wall's reference
#: radius is the sphere's) and its Hertz contacts last ~3.7% longer than the reference's.
HERTZ_OPEN = pytest.mark.xfail(
    strict=True,
    reason="YADE Hertz-Mindlin contacts last longer than the reference: a wall counts with the sphere "
    "radius (R* = R/2, +19%), a sphere pair +3.7% (unexplained)",
)


@pytest.fixture(autouse=True)
def yade():
    require_solver(registry.get_engine("yade").locate_solver)


def _dem(tmp_path, model, **extra):
    params = dict(
        engine="yade",
        model=model,
        box=(-0.01, 0.01, -0.01, 0.01, -0.01, 0.01),
        species=({"material": MATERIAL, "radius": R},),
        dt=DT,
        output=str(tmp_path / "out"),
        traj={"pfile": None},
        progress=False,
    )
    return simulation.DEM(**(params | extra))


def _track(sim, gap, tc, samples=200):
    """Run until contact starts, then sample ``gap()`` ``samples`` times over 1.5 ``tc``:
    returns the contact time (overlap crossings interpolated) and the sample times."""
    sim.run(max(1, int(0.5 * tc / DT)))  # still approaching: starts at 4 steps from contact
    chunk = max(1, int(1.5 * tc / DT / samples))
    times, gaps = [sim.time], [gap()]
    for _ in range(samples):
        sim.run(chunk)
        times.append(sim.time)
        gaps.append(gap())
    times, gaps = np.array(times), np.array(gaps)
    start = np.flatnonzero(gaps < 0)[0]
    end = np.flatnonzero(gaps[start:] >= 0)[0] + start

    def crossing(i):
        return times[i - 1] + (times[i] - times[i - 1]) * gaps[i - 1] / (gaps[i - 1] - gaps[i])

    return crossing(end) - crossing(start)


@pytest.mark.parametrize("model", [pytest.param(HertzMindlin, marks=HERTZ_OPEN), SpringDashpot])
def test_sphere_wall_impact_matches_reference(tmp_path, model):
    reference = model(material=dict(MATERIAL, radius=R)).displacement(V0)
    with _dem(tmp_path, model) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        # first touch after 0.5 tc + 4 steps
        sim.createParticles(
            1, "single", 0.0, 0.0, R + V0 * (0.5 * reference.contact_time + 4 * DT), vel=(0, 0, -V0)
        )
        tc = _track(sim, lambda: sim.extractCoords()[0, 2] - R, reference.contact_time)
        e = sim.extractVelocities()[0, 2] / V0
    assert tc == pytest.approx(reference.contact_time, rel=0.02)
    assert e == pytest.approx(reference.restitution, rel=0.02)


@pytest.mark.parametrize("model", [pytest.param(HertzMindlin, marks=HERTZ_OPEN), SpringDashpot])
def test_two_sphere_collision_matches_reference(tmp_path, model):
    sphere = dict(MATERIAL, radius=R)
    reference = model(material=sphere, partner=sphere).displacement(2 * V0)
    with _dem(tmp_path, model) as sim:
        start = R + V0 * (0.5 * reference.contact_time + 4 * DT)
        sim.createParticles(1, "single", -start, 0.0, 0.0, vel=(V0, 0, 0))
        sim.createParticles(1, "single", start, 0.0, 0.0, vel=(-V0, 0, 0))

        def gap():
            x = sim.extractCoords()[:, 0]
            return x[1] - x[0] - 2 * R

        tc = _track(sim, gap, reference.contact_time)
        v = sim.extractVelocities()[:, 0]
    assert tc == pytest.approx(reference.contact_time, rel=0.02)
    assert (v[1] - v[0]) / (2 * V0) == pytest.approx(reference.restitution, rel=0.02)
    assert v.sum() == pytest.approx(0.0, abs=1e-9)  # momentum


def _settle(tmp_path, engine, n=(6, 6, 6), steps=(8000, 4000, 8000)):
    """The settle benchmark (docs: benchmarks/settle.md) at small N, in a box with four
    frictional side walls instead of periodic x and y (YADE cannot have walls in a periodic
    cell): returns the kinetic energy every 200 steps and the bed's interior solid fraction."""
    r, a = 1e-3, 1.1 * 2e-3
    nx, ny, nz = n
    rng = np.random.default_rng(7)
    material = dict(MATERIAL, coefficientRestitution=0.3, coefficientFriction=0.5)
    sim = simulation.DEM(
        engine=engine,
        model=HertzMindlin,
        box=(0, nx * a, 0, ny * a, 0, (nz + 3) * a),
        gravity=(9.81, 0, 0, -1),
        species=({"material": material, "radius": r},),
        dt=1e-5,
        output=str(tmp_path / engine),
        traj={"pfile": None},
        progress=False,
    )
    with sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        for plane, length in (("xplane", nx * a), ("yplane", ny * a)):
            sim.setupWall(species=1, plane=plane, peq=0.0)
            sim.setupWall(species=1, plane=plane, peq=length)
        cells = np.stack(np.meshgrid(*(np.arange(k) for k in n), indexing="ij"), -1).reshape(-1, 3)
        centres = (cells + 0.5) * a + rng.uniform(-1, 1, cells.shape) * 0.45 * (a - 2 * r)
        for x, y, z in centres:
            sim.createParticles(1, "single", x, y, z)
        monitor = sim.monitor(quantities=("ke",), freq=200)
        for count in steps:
            sim.run(count)
        z = sim.extractCoords()[:, 2]
        ke = monitor.values["ke"]
    top = np.sort(z)[-nx * ny :].mean()  # mean height of the top layer's centres
    lo, hi = 2 * r, top - 2 * r
    # volume of each sphere inside the slab lo < z < hi
    a_, b_ = np.clip(lo - z, -r, r), np.clip(hi - z, -r, r)
    volume = np.pi * ((r**2 * b_ - b_**3 / 3) - (r**2 * a_ - a_**3 / 3))
    return ke, volume.sum() / (nx * a * ny * a * (hi - lo))


def test_settle_packing_matches_native(tmp_path):
    ke, phi = _settle(tmp_path, "yade")
    assert ke.max() / ke[-1] >= 1e3
    assert 0.5 <= phi <= 0.64  # looser than periodic: the side walls order the outer layers
    if "native" not in registry.available("engine"):
        message = (
            f"the native engine is not installed (pip install ./plugins/pygran-native); YADE gave {phi:.4f}"
        )
        if in_ci():
            pytest.fail(f"CI=true and {message}", pytrace=False)
        pytest.skip(message)
    _, phi_native = _settle(tmp_path, "native")
    assert phi == pytest.approx(phi_native, rel=0.02)


def test_yade_error_is_engine_error_and_the_session_continues(tmp_path):
    with _dem(tmp_path, HertzMindlin) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.0)
        with pytest.raises(EngineError, match="Body id out of range"):
            sim.command("O.bodies[12345].state.vel")
        sim.run(10)  # the worker survives a Python-level YADE error
        with pytest.raises(EngineError, match="SIGSEGV"):
            sim.command("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)")
        with pytest.raises(EngineError, match="worker is gone"):
            sim.run(10)
    with _dem(tmp_path, HertzMindlin) as sim:  # a new simulation starts a new worker
        assert sim.createParticles(1, "single", 0.0, 0.0, 0.0) == 1


def test_unsupported_requests_are_refused(tmp_path):
    with _dem(tmp_path, HertzMindlin, boundary=("p", "p", "f")) as sim:
        with pytest.raises(UnsupportedFeature, match="periodic"):
            sim.setupWall(species=1, plane="zplane", peq=0.0)
    with pytest.raises(UnsupportedFeature, match="thornton-ning"):
        _dem(tmp_path, ThorntonNing)
    spread = ({"material": MATERIAL, "radius": ("normal", R, R / 10)},)
    with pytest.raises(UnsupportedFeature, match="one radius per species"):
        _dem(tmp_path, SpringDashpot, species=spread)


def test_worker_is_killed_on_close(tmp_path):
    sim = _dem(tmp_path, HertzMindlin)
    process = sim.engine.worker.process
    sim.close()
    assert process.poll() is not None
    assert math.isfinite(process.returncode)


def test_a_silent_worker_is_stopped_after_the_timeout(tmp_path, monkeypatch):
    with _dem(tmp_path, HertzMindlin) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.0)
        monkeypatch.setenv("PYGRAN_YADE_TIMEOUT", "2")  # read at every answer
        process = sim.engine.worker.process
        os.kill(process.pid, signal.SIGSTOP)  # a hung worker: alive, never answering
        with pytest.raises(
            EngineError, match="did not answer within 2 s during run, so the worker was stopped"
        ):
            sim.run(10)
        assert process.poll() is not None
        with pytest.raises(EngineError, match="worker is gone"):
            sim.run(10)


def test_insertion_matches_native_for_the_same_seed(tmp_path):
    region = ("block", -9e-3, 9e-3, -9e-3, 9e-3, -9e-3, 9e-3)
    positions = {}
    for engine in ("yade", "native"):
        params = {
            "engine": engine,
            "model": HertzMindlin,
            "box": (-0.01, 0.01, -0.01, 0.01, -0.01, 0.01),
            "seed": 3,
            "species": ({"material": MATERIAL, "radius": R},),
            "output": str(tmp_path / engine),
            "dt": 1e-6,
            "traj": {"pfile": None},
            "progress": False,
        }
        with simulation.DEM(**params) as sim:
            sim.insert(species=1, value=60, region=region)
            positions[engine] = sim.extractCoords()
    assert positions["yade"].shape == (60, 3)
    np.testing.assert_array_equal(positions["yade"], positions["native"])


def test_insertion_by_rate(tmp_path):
    with _dem(tmp_path, HertzMindlin, gravity=None, dt=1e-6) as sim:
        sim.insert(
            species=1,
            insert="by_rate",
            rate=2000,
            freq=1000,
            duration=0.01,
            region=("block", -9e-3, 9e-3, -9e-3, 9e-3, -9e-3, 9e-3),
        )
        sim.run(15000)  # 15 ms, of which 10 ms insert
        assert len(sim.extractIds()) == pytest.approx(2000 * 0.01, abs=1)
