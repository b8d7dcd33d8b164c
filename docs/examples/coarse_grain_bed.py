"""The stress profile of a settled bed: a simulation on the native engine that writes its
contacts, then the coarse-grained density and vertical stress against the weight above.

Writes ``out-bed/`` (trajectory with contacts) and ``bed-stress.png`` in the current directory.
"""

import numpy as np

from pygran_core import analysis, params, simulation

radius = 1e-3
beads = dict(params.glass, youngsModulus=1e7, coefficientRestitution=0.3)
side = 12 * radius
with simulation.DEM(
    engine="native",
    model=simulation.models.HertzMindlin,
    box=(0, side, 0, side, 0, 0.07),
    boundary=("p", "p", "f"),  # periodic in x and y
    gravity=(9.81, 0, 0, -1),
    dt=2e-6,
    output="out-bed",
    species=({"material": beads, "radius": radius},),
    traj={"freq": 50000, "pfile": "traj.h5", "cfile": "traj.h5"},  # contacts in the same file
) as sim:
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    sim.insert(species=1, value=400, region=("block", 0, side, 0, side, 0.002, 0.07))
    sim.run(150000)  # 0.3 s: they fall and come to rest

bed = analysis.System(Particles="out-bed/traj.h5")  # system.Contacts comes with it
bed.goto(-1)
top = float((bed.Particles.z + bed.Particles.radius).max())
grid = analysis.Grid1D(axis="z", bins=240, range=(-0.005, top + 0.005))  # cells of w / 8; area: the box's
fields = analysis.CoarseGrain(bed, grid=grid, kernel="lucy", width=radius, density=beads["density"]).compute()

z = fields.coordinates[0]
dz = z[1] - z[0]
weight = 9.81 * np.cumsum((fields.density * dz)[::-1])[::-1]  # g times the mass above, per area
stress = fields.stress[:, 2, 2]
middle = np.argmin(abs(z - top / 2))
print(f"bed top at {top * 1e3:.1f} mm; bulk density at mid-height {fields.density[middle]:.0f} kg/m^3")
print(
    f"at z = {z[middle] * 1e3:.1f} mm: sigma_zz {stress[middle]:.1f} Pa, weight above {weight[middle]:.1f} Pa"
)

ax = fields.plot("stress_zz", label="sigma_zz")
ax.plot(z, weight, "--", label="g x mass above / area")
ax.legend()
ax.figure.savefig("bed-stress.png")
