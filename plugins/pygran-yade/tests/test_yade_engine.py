"""The YADE engine on the real YADE beyond the conformance suite: its clamped Hertz law and
restitution, plane walls and the settle scenario in periodic domains, insertion as native's,
and YADE failures as EngineError."""

from __future__ import annotations

import math
import os
import signal

import numpy as np
import pytest
from pygran_yade.engine import clamped_damping_ratio

from pygran_core import params, registry, simulation
from pygran_core.errors import EngineError, UnsupportedFeature
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.testing.solvers import in_ci, require_solver
from pygran_core.testing.validation import GRAVITY, SOFT, settle_setup

MATERIAL = dict(SOFT, characteristicVelocity=0.5)
R, V0, DT = 1e-3, 0.5, 1e-7


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


def _wall_impact(tmp_path, model, material):
    """Contact time and restitution of a sphere hitting a plane wall at ``V0``."""
    reference = model(material=dict(material, radius=R)).displacement(V0)
    with _dem(tmp_path, model, species=({"material": material, "radius": R},)) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        # first touch after 0.5 tc + 4 steps
        sim.createParticles(
            1, "single", 0.0, 0.0, R + V0 * (0.5 * reference.contact_time + 4 * DT), vel=(0, 0, -V0)
        )
        tc = _track(sim, lambda: sim.extractCoords()[0, 2] - R, reference.contact_time)
        return tc, sim.extractVelocities()[0, 2] / V0


def test_hertz_law_is_the_clamped_reference(tmp_path):
    """YADE's Hertz law is the reference with its force clamped at zero (limitForce=True)
    and the damping ratio that realises e: restitution e, contacts 3.6 % longer at e = 0.3."""
    e = MATERIAL["coefficientRestitution"]
    beta = -clamped_damping_ratio(e) / math.sqrt(5 / 6)  # the reference's beta for that ratio
    clamped = dict(
        MATERIAL, radius=R, coefficientRestitution=math.exp(beta * math.pi / math.sqrt(1 - beta**2))
    )
    expected = HertzMindlin(material=clamped, limitForce=True).displacement(V0)
    tc, restitution = _wall_impact(tmp_path, HertzMindlin, MATERIAL)
    assert restitution == pytest.approx(e, rel=0.02)
    assert tc == pytest.approx(expected.contact_time, rel=0.01)
    unclamped = HertzMindlin(material=dict(MATERIAL, radius=R)).displacement(V0)
    assert tc / unclamped.contact_time == pytest.approx(1.036, abs=0.01)


@pytest.mark.parametrize("boundary", [("p", "p", "f"), ("p", "f", "f")])
def test_plane_walls_hold_spheres_across_periodic_boundaries(tmp_path, boundary):
    """Spheres set on the floor every 1.25 mm along the periodic x axis (one across its
    ends) stay on it, and side walls (y planes) stop spheres thrown at them."""
    side = 0.01
    with _dem(
        tmp_path, HertzMindlin, box=(0, side, 0, side, 0, side), boundary=boundary, gravity=GRAVITY, dt=1e-5
    ) as sim:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
        floor = [
            (0.2 * R + 2.5e-3 * i + 1.25e-3 * j, 3.75e-3 + 2.5e-3 * j) for i in range(4) for j in range(2)
        ]
        for x, y in floor:
            sim.createParticles(1, "single", x, y, R)
        if boundary[1] == "f":
            for y, v in ((R, -0.05), (side - R, 0.05)):
                sim.setupWall(species=1, plane="yplane", peq=0.0 if y < side / 2 else side)
                sim.createParticles(1, "single", side / 2, y, 3 * R, vel=(0.0, v, 0.0))
        sim.run(3000)  # 30 ms: a free fall of 4.4 mm
        x = sim.extractCoords()
    assert len(x) == len(floor) + (2 if boundary[1] == "f" else 0)
    assert np.all(x[:, 2] > 0.99 * R), x
    assert np.all((x[:, 1] > 0.99 * R) & (x[:, 1] < side - 0.99 * R)), x


def _settled_bed(tmp_path, engine, shape=(8, 8, 6)):
    """The settle scenario (benchmarks/settle.md, periodic in x and y, floor at z = 0) with
    ``shape`` spheres: 8000 + 4000 steps, then 18000 more for the bed to come to rest.
    Returns the kinetic energy every 200 steps and the bed's packing fraction: the solid
    fraction below the mean centre height of its top layer (the highest nx * ny spheres)."""
    with settle_setup(engine, tmp_path / engine, shape) as sim:
        monitor = sim.monitor(quantities=("ke",), freq=200)
        for steps in (8000, 4000, 18000):
            sim.run(steps)
        z, r = sim.extractCoords()[:, 2], sim.extractRadii()
        (xlo, xhi), (ylo, yhi), _ = sim.spec.domain.box
    assert len(z) == np.prod(shape), "spheres were lost"
    top = np.sort(z)[-shape[0] * shape[1] :].mean()
    below = np.clip(top - z, -r, r)  # the part of each sphere below the top: a cap of height r + below
    volume = np.pi * (r**2 * (below + r) - (below**3 + r**3) / 3)
    return monitor.values["ke"], volume.sum() / ((xhi - xlo) * (yhi - ylo) * top)


def test_settle_in_a_periodic_domain_matches_native(tmp_path):
    ke, phi = _settled_bed(tmp_path, "yade")
    assert ke.max() / ke[-1] >= 1e3
    assert 0.54 <= phi <= 0.60, phi
    if "native" not in registry.available("engine"):
        message = (
            f"the native engine is not installed (pip install ./plugins/pygran-native); YADE gave {phi:.4f}"
        )
        if in_ci():
            pytest.fail(f"CI=true and {message}", pytrace=False)
        pytest.skip(message)
    _, phi_native = _settled_bed(tmp_path, "native")
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
    with _dem(tmp_path, HertzMindlin, boundary=("p", "f", "f")) as sim:
        with pytest.raises(UnsupportedFeature, match="a plane wall across a periodic axis"):
            sim.setupWall(species=1, plane="xplane", peq=0.0)
    with _dem(tmp_path, HertzMindlin, boundary=("p", "p", "p")) as sim:
        with pytest.raises(UnsupportedFeature, match="periodic along every axis"):
            sim.setupWall(species=1, wtype="primitive", axis="z", centre=(0.0, 0.0), radius=5e-3)
    with pytest.raises(UnsupportedFeature, match="thornton-ning"):
        _dem(tmp_path, ThorntonNing)
    spread = ({"material": MATERIAL, "radius": ("normal", R, R / 10)},)
    with pytest.raises(UnsupportedFeature, match="one radius per species"):
        _dem(tmp_path, SpringDashpot, species=spread)


def test_run_without_a_time_step_takes_a_fifth_of_the_p_wave_time_step(tmp_path):
    with _dem(tmp_path, HertzMindlin, dt=None) as sim:
        sim.createParticles(1, "single", 0.0, 0.0, 0.0, vel=(0.1, 0.0, 0.0))
        sim.run(10)
        dt, t, x = sim.engine.dt, sim.time, sim.extractCoords()[0, 0]
    # YADE's utils.PWaveTimeStep: the smallest r / sqrt(E / rho) of the spheres
    expected = 0.2 * R / math.sqrt(MATERIAL["youngsModulus"] / MATERIAL["density"])
    assert dt == pytest.approx(expected, rel=1e-9)
    assert t == pytest.approx(10 * expected, rel=1e-12) and x == pytest.approx(0.1 * t, rel=1e-9)
    assert "0.2 x PWaveTimeStep" in (tmp_path / "out" / "pygran.log").read_text()


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
        # the run's first request (the time-step check reads the particles) is not answered
        with pytest.raises(
            EngineError, match="did not answer within 2 s during extract, so the worker was stopped"
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


@pytest.mark.parametrize("name", ["steel", "organic"])
def test_original_materials_bounce_with_their_restitution(tmp_path, name):
    """The original PyGran materials without cohesion, stiff and soft, run on YADE: a sphere
    hitting the floor at 0.5 m/s rebounds with their restitution, 0.9 (the conformance
    suite's impacts are at e = 0.5; YADE's damping ratio for e is its own, clamped law)."""
    material = getattr(params, name)
    _, e = _wall_impact(tmp_path, HertzMindlin, material)
    assert e == pytest.approx(material["coefficientRestitution"], rel=0.02)


@pytest.mark.parametrize(("name", "missing"), [("glass", "cohesion"), ("sodaLimeGlass", "rolling friction")])
def test_materials_with_cohesion_or_rolling_friction_are_refused(tmp_path, name, missing):
    """YADE has neither cohesion nor a rolling-resistance law matching LIGGGHTS' (README)."""
    with pytest.raises(UnsupportedFeature, match=f"does not support {missing}.*Engines that can: liggghts"):
        _dem(tmp_path, HertzMindlin, species=({"material": getattr(params, name), "radius": R},))
