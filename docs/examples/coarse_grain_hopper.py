"""The velocity field of a hopper discharge: a simulation on the native engine, then the
angle-averaged density and velocity on rings about the hopper's axis, over the discharge.

The hopper is the original examples' silo (tests/data/meshes/silo.stl, in mm: a cone from
r = 0.3 mm at its outlet, z = 0, to r = 1 mm at z = 3 mm) with a stopper across the outlet.
Writes ``out-hopper/`` (the trajectory), ``hopper-velocity.png`` and ``hopper.vti`` (for
ParaView) in the current directory.
"""

from pathlib import Path

import numpy as np

from pygran_core import analysis, params, simulation

silo = Path(__file__).resolve().parents[2] / "tests" / "data" / "meshes" / "silo.stl"
radius, density = 5e-5, 2500.0
sand = dict(params.cohesionless, density=density, coefficientRestitution=0.5)
with simulation.DEM(
    engine="native",
    model=simulation.models.HertzMindlin,
    box=(-1.1e-3, 1.1e-3, -1.1e-3, 1.1e-3, -1e-3, 5e-3),
    gravity=(9.81, 0, 0, -1),
    dt=5e-7,
    output="out-hopper",
    species=({"material": sand, "radius": radius},),
    mesh={"silo": {"file": str(silo), "mtype": "mesh/surface", "args": ("scale 1e-3",)}},
    traj={
        "freq": 2000,
        "pfile": "traj.h5",
        "args": ("x", "y", "z", "radius", "vx", "vy", "vz", "id", "type"),
    },
) as sim:
    sim.expect_outflow("z-")  # what leaves through the outlet falls out of the box
    stopper = sim.setupWall(plane="zplane", peq=0.0)
    sim.insert(species=1, value=800, region=("cylinder", "z", 0.0, 0.0, 5.5e-4, 1.4e-3, 4.9e-3))
    sim.run(70000)  # fall into the cone and settle on the stopper
    start = sim.step
    sim.remove(stopper)
    sim.run(30000)  # discharge, a frame every 2000 steps

hopper = analysis.System(Particles="out-hopper/traj.h5")
above = {}  # spheres in the hopper (above its outlet) at each frame of the steady discharge
for k in hopper.frames():
    if hopper.timestep >= start + 10000:
        above[k] = int(np.sum(hopper.Particles.z > 0))
frames = sorted(above)
grid = analysis.GridCylindrical(axis="z", bins=(16, 42), range=((0, 8e-4), (-6e-4, 1.5e-3)))
cg = analysis.CoarseGrain(hopper, grid=grid, kernel="lucy", width=radius, density=density)
fields = cg.compute(frames=slice(frames[0], frames[-1] + 1))
print(fields)

r, z = fields.coordinates
dr = r[1] - r[0]
speed = -fields.velocity[..., 2]  # downwards, m/s
flux = -fields.momentum[..., 2]  # kg / (m^2 s)
at = np.argmin(abs(z - 3 * radius))  # just above the outlet
rate = np.sum(flux[:, at] * 2 * np.pi * r * dr)  # kg/s through that cross-section
mass = 4 / 3 * np.pi * radius**3 * density
seconds = (len(frames) - 1) * 2000 * 5e-7
counted = (above[frames[0]] - above[frames[-1]]) * mass / seconds
print(
    f"mass flow through the outlet: {rate * 1e6:.1f} mg/s from the fields, {counted * 1e6:.1f} mg/s counted"
)
axis = speed[0, (z > 0) & (z < 5e-4)].mean()
print(f"downward speed near the axis above the outlet {axis:.3f} m/s")

fields.plot("density", quiver=True, cmap="viridis", path="hopper-velocity.png")
fields.to_vtk("hopper.vti")
print("wrote hopper-velocity.png and hopper.vti")
