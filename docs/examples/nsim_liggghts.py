"""Two simulations at once on LIGGGHTS, one per value of the restitution coefficient.

Run with ``mpirun -np 2 python nsim_liggghts.py`` (or ``-np 4``: two ranks per simulation).
``nSim=2`` splits the MPI ranks into two groups; each runs its own simulation with its own
entry of every list-valued species or material entry, and writes to ``out-nsim/run0`` and
``out-nsim/run1``.
"""

from pygran_core import params, simulation

beads = dict(params.glass, youngsModulus=1e7, coefficientRestitution=[0.3, 0.9])  # one per run

with simulation.DEM(
    engine="liggghts",
    nSim=2,
    model=simulation.models.HertzMindlin,
    box=(-3e-3, 3e-3, -3e-3, 3e-3, 0, 1.5e-2),
    boundary=("p", "p", "f"),
    gravity=(9.81, 0, 0, -1),
    dt=4e-6,
    output="out-nsim",
    species=({"material": beads, "radius": 5e-4},),
    traj={"freq": 2000, "pfile": "traj.dump"},
) as sim:
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    sim.insert(species=1, value=100, region=("block", -3e-3, 3e-3, -3e-3, 3e-3, 1e-3, 1.5e-2))
    sim.run(10000)
    v = sim.extractVelocities()
    print(
        f"{sim.engine.output.name}: e = {sim.engine.spec.species[0].material['coefficientRestitution']}, "
        f"{len(v)} particles, mean speed {abs(v).mean():.3f} m/s"
    )
