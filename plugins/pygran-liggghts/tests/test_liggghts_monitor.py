"""Monitors of some species only on real LIGGGHTS, PyGran 1.x's way: ``monitor(var=...,
species=k, name=..., file=..., nevery=, nrepeat=, nfreq=)``."""

import math

import numpy as np
import pytest
from pygran_liggghts.library import find_library

from pygran_core import params, simulation
from pygran_core.errors import UnsupportedFeature
from pygran_core.testing.solvers import require_solver

R = 1e-3


def test_monitors_of_one_species(tmp_path):
    """Three spheres of species 1 move at 0.1 m/s, two of species 2 (half the radius) spin
    at 50 rad/s, far apart, without gravity: each monitor gives its species' energy, every
    nfreq steps, as 1/2 m v^2 and 1/2 (2/5 m r^2) w^2 over that species' spheres."""
    require_solver(find_library)
    organic = params.organic
    script = {
        "engine": "liggghts",
        "box": (-0.01, 0.01, -0.01, 0.01, -0.01, 0.01),
        "boundary": ("p", "p", "p"),
        "species": ({"material": organic, "radius": R}, {"material": organic, "radius": R / 2}),
        "dt": 1e-6,
        "output": str(tmp_path),
        "traj": {"pfile": None},
        "progress": False,
    }
    with simulation.DEM(**script) as sim:
        sim.createParticles(
            1, "single", [(-0.005, -0.005, 0), (0, -0.005, 0), (0.005, -0.005, 0)], vel=(0.1, 0, 0)
        )
        sim.createParticles(2, "single", [(-0.005, 0.005, 0), (0.005, 0.005, 0)], omega=(0, 0, 50))
        ke1 = sim.monitor(var="ke", species=1, name="ke1", file="ke1.dat", nevery=10, nrepeat=2, nfreq=100)
        ke2 = sim.monitor(var="ke", species=2, name="ke2", file="ke2.dat", nevery=100, nfreq=100)
        spin2 = sim.monitor(var="erotate/sphere", species=2, name="spin2", nevery=100, nfreq=100)
        spin = sim.monitor(var="erotate/sphere", species="all", name="spin", nevery=100, nfreq=100)
        sim.run(300)
    mass = organic["density"] * 4 / 3 * math.pi * np.array([R, R / 2]) ** 3
    moving = 3 * 0.5 * mass[0] * 0.1**2
    spinning = 2 * 0.5 * 0.4 * mass[1] * (R / 2) ** 2 * 50**2
    np.testing.assert_array_equal(ke1.values["step"], [100, 200, 300])
    np.testing.assert_allclose(ke1.values["ke"], moving, rtol=1e-12)
    np.testing.assert_array_equal(ke2.values["ke"], [0, 0, 0, 0])  # steps 0 to 300
    np.testing.assert_allclose(spin2.values["erotate/sphere"], spinning, rtol=1e-12)
    np.testing.assert_allclose(spin.values["erotate/sphere"], spinning, rtol=1e-12)
    assert (tmp_path / "ke1.dat").read_text().splitlines()[2].split() == [
        "100",
        repr(float(ke1.values["ke"][0])),
    ]


def test_a_monitor_of_a_multisphere_species_is_refused(tmp_path):
    """LIGGGHTS' energies of multisphere bodies are over every body: a monitor of the
    multisphere species alone is refused, naming it."""
    require_solver(find_library)
    organic = params.organic
    script = {
        "engine": "liggghts",
        "box": (-0.01, 0.01, -0.01, 0.01, -0.01, 0.01),
        "species": (
            {"material": organic, "radius": R},
            {"material": organic, "style": "multisphere", "function": lambda: [(0, 0, 0, R), (R, 0, 0, R)]},
        ),
        "dt": 1e-6,
        "output": str(tmp_path),
        "traj": {"pfile": None},
        "progress": False,
    }
    with simulation.DEM(**script) as sim:
        sim.monitor(var="ke", species=2, name="bodies", nevery=10, nfreq=10)
        with pytest.raises(UnsupportedFeature, match=r"multisphere species \[2\]"):
            sim.run(10)
