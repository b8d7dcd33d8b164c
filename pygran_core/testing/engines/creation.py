"""The engine suite's checks of registration, every ``createParticles`` form, the extracts and
``close``."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from pygran_core.errors import EngineError, UnsupportedFeature
from pygran_core.hookspecs import CAPABILITIES
from pygran_core.simulation.dem import DEM
from pygran_core.testing.engines.base import RADIUS, SUITE_FEATURES, EngineSuite, Outcome, attempt

#: The createParticles scenario's (N, 3) array, lattice and random region (see ``created``).
ARRAY = np.array([[x, y, -7e-3] for x in (-3e-3, 0.0, 3e-3) for y in (-3e-3, 0.0, 3e-3)])
LATTICE_SPACING = 2.5 * RADIUS
LATTICE_BOUNDS = tuple(v for n in (3, 2, 2) for v in (0.25 * LATTICE_SPACING, (n + 0.25) * LATTICE_SPACING))
LATTICE_REGION = ("block", *LATTICE_BOUNDS)
RANDOM_REGION = ("block", -9e-3, -1e-3, -9e-3, -1e-3, -5e-3, 5e-3)


def extracted(sim: DEM) -> dict[str, np.ndarray]:
    """Every extract* of ``sim``."""
    return {
        "id": sim.extractIds(),
        "x": sim.extractCoords(),
        "v": sim.extractVelocities(),
        "omega": sim.extractOmegas(),
        "f": sim.extractForces(),
        "radius": sim.extractRadii(),
    }


class CreationChecks(EngineSuite):
    """``createParticles`` in each form, the extracts, the declarations and ``close``."""

    @pytest.fixture(scope="class")
    @classmethod
    def created(cls, tmp_path_factory) -> dict[str, Outcome]:
        """One simulation without gravity, each ``createParticles`` form in its own part of the
        box: what each created (or raised), the particles after 200 steps, the engine's name
        and capabilities, and what calls raise once it is closed."""
        suite = cls()
        dt = suite.dt(0.8 * RADIUS)
        output = tmp_path_factory.mktemp("created")
        forms: dict[str, tuple[Any, ...]] = {
            "single": (
                (-6e-3, 6e-3, 8e-3, {"vel": (0.1, -0.2, 0.05), "omega": (1.0, 2.0, 3.0)}),
                (-6e-3, 2e-3, 8e-3, {"radius": 0.8 * RADIUS}),
            ),
            "array": (ARRAY, {"vel": (0.0, 0.0, 0.1)}),
            "lattice": (LATTICE_SPACING, {"region": LATTICE_REGION}),
            "random": (20, {"region": RANDOM_REGION}),
        }

        def run(sim: DEM) -> tuple[Any, int, float]:
            """The particles after 200 steps, the step and the time."""
            sim.run(200)
            return extracted(sim), sim.step, sim.time

        def make(sim: DEM, form: str) -> tuple[Any, np.ndarray]:
            """What ``createParticles`` returned, and the ids of the particles it made."""
            before = sim.extractIds()
            made: int | list[int]
            if form == "single":
                made = [sim.createParticles(1, "single", *xyz, **kw) for *xyz, kw in forms[form]]
            else:
                first, keywords = forms[form]
                made = sim.createParticles(1, "single" if form == "array" else form, first, **keywords)
            return made, np.setdiff1d(sim.extractIds(), before)

        try:
            sim = suite.dem(output, dt=dt)
        except Exception as exc:  # noqa: BLE001 - every test of the scenario reads it
            return {key: Outcome(error=exc) for key in ("engine", *forms, "start", "run", "closed")}
        results = {"engine": Outcome((sim.engine.name, sim.engine.capabilities))}
        with sim:
            for form in forms:
                results[form] = attempt(partial(make, sim, form))
            results["start"] = attempt(partial(extracted, sim))
            results["run"] = attempt(partial(run, sim))
        closed = {}
        for name, call in (("close", sim.close), ("extract", sim.extractCoords), ("run", lambda: sim.run(1))):
            closed[name] = attempt(call).error
        results["closed"] = Outcome((closed, (output / "pygran.log").read_text()))
        return results

    def test_declarations(self, created):
        """Known capabilities; refusals are suite features, not capabilities; the engine
        object declares what its plugin registered."""
        assert self.capabilities <= CAPABILITIES, self.capabilities - CAPABILITIES
        assert self.refuses <= set(SUITE_FEATURES), self.refuses - set(SUITE_FEATURES)
        if "raw-commands" in self.capabilities:
            assert self.raw_command, "an engine declaring raw-commands gives raw_command for its check"
        assert created["engine"].get() == (self.engine, self.capabilities)

    def created_by(self, created: dict[str, Outcome], form: str) -> np.ndarray:
        """The ids of the particles ``form`` created, once its count is checked."""
        made, ids = created[form].get()
        counts: dict[str, int | list[int]] = {"single": [1, 1], "array": 9, "lattice": 12, "random": 20}
        count = counts[form]
        assert made == count and len(ids) == np.sum(count), (made, ids)
        return ids

    def test_create_single_and_extract(self, created):
        """Two spheres created one by one, with velocity and spin or a radius of their own,
        are where they were put and move freely (no gravity); every extract* gives them in
        id order."""
        ids = self.created_by(created, "single")
        start = created["start"].get()
        (end, step, time), dt = created["run"].get(), self.dt(0.8 * RADIUS)
        x0 = np.array([[-6e-3, 6e-3, 8e-3], [-6e-3, 2e-3, 8e-3]])
        v0 = np.array([[0.1, -0.2, 0.05], [0.0, 0.0, 0.0]])
        w0 = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
        assert len(ids) == 2 and ids[0] < ids[1]
        first = np.isin(start["id"], ids)
        np.testing.assert_allclose(start["x"][first], x0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["v"][first], v0, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["omega"][first], w0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(start["radius"][first], [RADIUS, 0.8 * RADIUS], rtol=1e-12)
        assert step == 200 and time == pytest.approx(200 * dt, rel=1e-12)
        np.testing.assert_array_equal(end["id"], start["id"])
        np.testing.assert_allclose(end["x"][first], x0 + v0 * time, rtol=0, atol=1e-12)
        np.testing.assert_allclose(end["v"][first], v0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(end["omega"][first], w0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(end["f"], 0.0, rtol=0, atol=1e-15)

    def test_create_array(self, created):
        """An (N, 3) array of positions gives one sphere at each row, in the order of the rows."""
        if not self.supports("create-array"):
            with pytest.raises(UnsupportedFeature):
                created["array"].get()
            return
        ids = self.created_by(created, "array")
        start = created["start"].get()
        chosen = np.isin(start["id"], ids)
        np.testing.assert_allclose(start["x"][chosen], ARRAY, rtol=0, atol=1e-15)
        np.testing.assert_allclose(start["v"][chosen], [[0.0, 0.0, 0.1]] * len(ARRAY), rtol=0, atol=1e-15)

    def test_create_lattice(self, created):
        """A simple cubic lattice of spacing ``a`` filling a block a quarter spacing off the
        lattice: 3 x 2 x 2 sites, spaced ``a`` along each axis, inside the block."""
        if not self.supports("create-lattice"):
            with pytest.raises(UnsupportedFeature):
                created["lattice"].get()
            return
        ids = self.created_by(created, "lattice")
        start = created["start"].get()
        x, a = start["x"][np.isin(start["id"], ids)], LATTICE_SPACING
        bounds = np.reshape(LATTICE_BOUNDS, (3, 2))
        for axis, n in enumerate((3, 2, 2)):
            levels = np.unique(np.round(x[:, axis] / a, 6))
            assert len(levels) == n, (axis, levels)
            np.testing.assert_allclose(np.diff(levels), 1.0, rtol=1e-9)
            assert np.all((bounds[axis, 0] <= x[:, axis]) & (x[:, axis] <= bounds[axis, 1]))

    def test_create_random(self, created):
        """20 spheres placed at random in a block: all whole inside it, none overlapping."""
        if not self.supports("create-random"):
            with pytest.raises(UnsupportedFeature):
                created["random"].get()
            return
        ids = self.created_by(created, "random")
        start = created["start"].get()
        chosen = np.isin(start["id"], ids)
        x, r = start["x"][chosen], start["radius"][chosen]
        bounds = np.reshape(RANDOM_REGION[1:], (3, 2))
        assert np.all((x - r[:, None] >= bounds[:, 0] - 1e-12) & (x + r[:, None] <= bounds[:, 1] + 1e-12))
        assert pdist(x).min() >= 2 * RADIUS * (1 - 1e-9)

    def test_close(self, created):
        """A closed simulation refuses calls with EngineError; closing twice is harmless."""
        closed, log = created["closed"].get()
        assert closed["close"] is None
        assert isinstance(closed["extract"], EngineError) and isinstance(closed["run"], EngineError)
        assert "engine closed at step 200" in log
