"""Lost particles: every engine counts them per run, warns with where and why, or logs a declared outflow."""

import math
import warnings

import numpy as np
import pytest

from pygran_core import Engine, params
from pygran_core.errors import ConfigError, LostParticlesWarning, TimeStepWarning
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.engine import LostParticles
from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.simulation.specs import parse_simulation

ENGINES = ("native", "yade", "liggghts")
BOX = (0.0, 0.02, 0.0, 0.02, 0.0, 0.02)
R = 1e-3


def _sim(engine, tmp_path, **extra):
    settings = {
        "engine": engine,
        "model": HertzMindlin,
        "box": BOX,
        "species": ({"material": dict(params.organic), "radius": R},),
        "gravity": (9.81, 0, 0, -1),
        "output": str(tmp_path / engine),
        "traj": {"pfile": None},
        "progress": False,
        "dt": 1e-5,
    }
    return DEM(**settings | extra)


def _bed(sim):
    positions = np.stack(np.meshgrid(*[np.arange(2e-3, 0.019, 4e-3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return sim.createParticles(1, "single", positions)


@pytest.mark.parametrize("engine", ENGINES)
def test_particles_falling_through_an_open_floor_are_reported(engine, tmp_path):
    with _sim(engine, tmp_path) as sim:
        count = _bed(sim)
        with pytest.warns(LostParticlesWarning) as caught:
            sim.run(8000)  # 80 ms: the top layer falls 3 cm, out of the 2 cm box
        (warning,) = caught
        text = str(warning.message)
        assert sim.engine.lost == count == 125 and sim.engine.last_lost.where == {"z-": 125}
        assert text.startswith("125 particles lost in the run from step 0 to 8000: 125 through z-")
        speed = sim.engine.last_lost.max_speed
        if speed is not None:  # the speed they left at: at least the top layer's after 18 mm
            assert math.sqrt(2 * 9.81 * 0.018) < speed < 9.81 * 0.08
            assert f"they left at up to {speed:.3g} m/s through z-, where no wall holds them" in text
        else:
            assert "they left through z-, where no wall holds them" in text
        watched = type(sim.engine)._lost_since_last is Engine._lost_since_last  # found missing
        assert ("does not report lost particles" in text) == watched
        assert "expect_outflow('z-')" in text and warning.filename == __file__
        assert text in (sim.output / "pygran.log").read_text()
        assert len(sim.extractCoords()) == 0


@pytest.mark.parametrize("engine", ENGINES)
def test_a_declared_outflow_is_logged_not_warned(engine, tmp_path):
    with _sim(engine, tmp_path) as sim:
        sim.engine.expect_outflow("z-")
        _bed(sim)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sim.run(8000)
        assert sim.engine.lost == 125
        log = (sim.output / "pygran.log").read_text()
        assert "125 particles left through the expected outflow (z-) in the run from step 0 to 8000" in log


def test_outflow_faces_are_checked(tmp_path):
    with _sim("native", tmp_path, boundary=("p", "p", "f")) as sim:
        with pytest.raises(ConfigError, match="Unknown outflow face 'z'"):
            sim.engine.expect_outflow("z")
        with pytest.raises(ConfigError, match="outflow face 'x-': the x axis is periodic"):
            sim.engine.expect_outflow("x-")


@pytest.mark.parametrize("engine", ("native", "yade"))
def test_particles_flying_out_of_a_walled_box_blame_the_time_step(engine, tmp_path):
    material = dict(params.organic)
    with _sim(engine, tmp_path, box=(0.0, 0.01, 0.0, 0.01, 0.0, 0.01), gravity=None) as sim:
        for plane in ("xplane", "yplane", "zplane"):
            sim.setupWall(species=1, plane=plane, peq=0.0)
            sim.setupWall(species=1, plane=plane, peq=0.01)
        centres = np.stack(np.meshgrid(*[np.arange(1.25e-3, 0.01, 2.5e-3)] * 3, indexing="ij"), -1)
        velocities = np.random.default_rng(1).uniform(-0.1, 0.1, (64, 3))
        for centre, velocity in zip(centres.reshape(-1, 3), velocities):
            sim.createParticles(1, "single", *centre, vel=tuple(velocity))
        pair = HertzMindlin(material=dict(material, radius=R), partner=dict(material, radius=R))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sim.engine.run(2000, dt=pair.contactTime(), check_dt=False)  # one step per contact
    lost = sim.engine.last_lost
    given = max(np.linalg.norm(velocities, axis=1))
    assert lost.count == 64 and set(lost.where) <= {"x-", "x+", "y-", "y+", "z-", "z+"}
    assert [w.category for w in caught] == [TimeStepWarning, LostParticlesWarning]
    text = str(caught[1].message)
    if lost.max_speed is not None:  # the engine reports the speeds they left at (YADE)
        assert lost.max_speed > 10 * given
        seen = f"speeds up to {lost.max_speed:.3g} m/s, over 10 times the {given:.3g} m/s the simulation"
        assert f"{seen} explains: the time step is probably too large: dt = " in text
    else:  # all found missing (native), none left to go by: the faces, and the time-step check
        assert "(a contact too short to resolve lets particles pass through walls): the time step is" in text
    assert "1.0 times the contact time" in text


class Vanishing(Engine):
    """An engine that does not count its lost particles: ``_advance`` runs a scripted loss."""

    name = "vanishing"
    capabilities = frozenset({"spring-dashpot", "periodic"})

    def __init__(self, output, x, v, losses):
        spec = parse_simulation(
            {
                "box": (0, 1, 0, 1, 0, 1),
                "boundary": ("p", "f", "f"),
                "output": str(output),
                "traj": {"pfile": None},
                "progress": False,
                "dt": 0.01,
            },
            "vanishing",
            SpringDashpot,
        )
        super().__init__(spec)
        self.ids, self.x, self.v = np.arange(1, len(x) + 1), np.array(x, float), np.array(v, float)
        self.losses = list(losses)  # per piece of the run: the ids to drop and to make non-finite

    def _advance(self, nsteps):
        gone, broken = self.losses.pop(0)
        self.x[np.isin(self.ids, broken)] = np.nan
        keep = ~np.isin(self.ids, gone)
        self.ids, self.x, self.v = self.ids[keep], self.x[keep], self.v[keep]

    def _extract(self, quantity):
        return {"id": self.ids, "x": self.x, "v": self.v, "type": np.ones(len(self.ids), int)}.get(
            quantity, np.full(len(self.ids), 0.01)
        )


def test_an_engine_that_does_not_count_is_watched(tmp_path):
    x = [(0.5, 0.5, 0.5), (0.5, 0.9, 0.5), (0.5, 0.5, 0.9), (0.2, 0.5, 0.5), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5)]
    v = [(0, 0, 0), (0, 3.0, 0), (0, 0, 1.0), (-50.0, 0, 0), (0, 0, 0), (40.0, 0, 0)]
    # run 1 (0.1 s): 1 and 4 vanish without heading for a fixed face (4 moves along the
    # periodic x axis), 2 heads out through y+, 3 through z+, and 6 is left far too fast;
    # run 2: 5 turns non-finite and stays, 6 vanishes; run 3: nothing new
    losses = [([1, 2, 3, 4], []), ([6], [5]), ([], [])]
    with Vanishing(tmp_path, x, v, losses) as engine:
        engine.max_run_chunks = 1
        with pytest.warns(LostParticlesWarning) as caught:
            engine.run(10)
        assert engine.last_lost.where == {"unknown": 2, "y+": 1, "z+": 1}
        assert engine.last_lost.max_speed is None  # the speeds they left at are unknown
        assert "speeds up to 40 m/s, over 10 times the 1 m/s the simulation explains" in str(
            caught[0].message
        )
        assert "does not report lost particles" in str(caught[0].message)
        with pytest.warns(LostParticlesWarning, match="1 became non-finite.*; non-finite positions"):
            engine.run(10)
        assert engine.last_lost == LostParticles(2, {"unknown": 1, "non-finite": 1})
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            engine.run(10)  # the non-finite particle is counted once
        assert engine.lost == 6 and engine.last_lost == LostParticles()
