"""Analyse an existing LIGGGHTS run: particles from dump files, walls from VTK files.

The data are three frames of a real LIGGGHTS hopper discharge (docs/examples/data).
Run from anywhere: ``python docs/examples/analyse_liggghts.py``.
"""

from pathlib import Path

import numpy as np

from pygran_core import analysis

DATA = Path(__file__).parent / "data" / "liggghts-hopper"

# One System moves the particles and the wall meshes through the frames together.
hopper = analysis.System(
    Particles=str(DATA / "particles*.dump"),  # a glob, read in natural order (2 before 10)
    Mesh=str(DATA / "mesh*.vtk"),
    units="si",
)
print(f"{len(hopper)} frames")

for frame in hopper.frames():  # loads each frame from the first, yields its index
    P = hopper.Particles
    print(f"frame {frame}: step {hopper.timestep}, {len(P)} particles, {hopper.Mesh.nCells()} wall cells")

hopper.goto(-1)  # random access; negative counts from the end
P = hopper.Particles
print("columns:", ", ".join(P.keys()))

# Selections are numpy boolean masks; the result is again a Particles object.
low = P[P.z < 1e-3]
moving = P[np.sqrt(P.vx**2 + P.vy**2 + P.vz**2) > 0.05]
print(f"{len(low)} particles below z = 1 mm, {len(moving)} faster than 5 cm/s")

# Statistics of the last frame
neighbors = analysis.equilibrium.Neighbors(P)
rdf = P.computeRDF()
print(f"mean coordination number {neighbors.coon.mean():.2f}")
peak = np.argmax(rdf.g)
print(f"RDF peak g = {rdf.g[peak]:.1f} at r = {rdf.r[peak]:.2e} m (2 radii = {2 * P.radius.mean():.1e} m)")
print(f"radius of gyration {P.computeROG():.2e} m, centre of mass {P.computeCOM()} m")

# Time series. Particles are matched by id across frames, so N may change (here particles
# leave the box). Flow rate: particles crossing the plane z = 1 mm downwards. A dump holds
# step numbers, not times: with dt=1 the rate is per step; pass the run's time step instead
# for a rate per second.
series = analysis.dynamics.Temporal(hopper)
print("granular temperature per frame:", series.granularTemperature())
steps, rate = series.flowRate(point=(0, 0, 1e-3), normal=(0, 0, -1), dt=1)
for step, r in zip(steps, rate):
    print(f"around step {step:.0f}: {r * 1000:.1f} particles per 1000 steps")

# Write the last frame in another format (the extension picks the writer).
low.write("low.h5")
print("wrote", len(analysis.System(Particles="low.h5").Particles), "particles to low.h5")
