"""PyGran 1.x's createParticles lattice: the same call, the same particles on native and LIGGGHTS."""

import numpy as np

from PyGran import analysis, simulation

ENGINES = ["native", "liggghts"]


def require(engine):
    if engine == "liggghts":
        from pygran_liggghts.library import find_library

        from pygran_core.testing.solvers import require_solver

        require_solver(find_library)


def lattice(engine, output):
    """A lattice of spacing 0.45 mm in a 2 mm x 2 mm x 1 mm block, created and written once."""
    from PyGran.params import glass

    params = {
        "engine": engine,
        "box": (-1e-3, 1e-3, -1e-3, 1e-3, 0, 2e-3),
        "species": ({"material": glass, "radius": 2e-4},),
        "dt": 4e-8,
        "output": output,
        "traj": {"freq": 10, "pfile": "traj.dump", "args": ("id", "type", "x", "y", "z", "radius")},
    }
    with simulation.DEM(**params) as sim:
        made = sim.createParticles(1, "lattice", 4.5e-4, region=("block", -1e-3, 1e-3, -1e-3, 1e-3, 0, 1e-3))
        sim.run(10)
    return made


def test_the_same_lattice_call_gives_the_same_particles(tmp_path):
    """Sites from each lower bound plus half a spacing (-0.775, -0.325, 0.125, 0.575 mm in x
    and y, 0.225 and 0.675 mm in z) where a whole sphere fits: 32 on each engine, at the same
    places, in the trajectory each writes (on LIGGGHTS, its own dump)."""
    frames = {}
    for engine in ENGINES:
        require(engine)
        assert lattice(engine, str(tmp_path / engine)) == 32
        with analysis.System(Particles=str(tmp_path / engine / "traj.dump")) as system:
            particles = system.Particles
            frames[engine] = np.column_stack([particles.x, particles.y, particles.z])
    axis = np.array([-0.775, -0.325, 0.125, 0.575]) * 1e-3
    expected = np.array([(x, y, z) for x in axis for y in axis for z in (2.25e-4, 6.75e-4)])
    for engine in ENGINES:
        positions = frames[engine][np.lexsort(frames[engine].T[::-1])]
        np.testing.assert_allclose(positions, expected, atol=1e-9)  # dumps keep 6 digits
