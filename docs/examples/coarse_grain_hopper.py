"""The velocity field of a hopper discharge, averaged over the angle and over three frames.

The data are three frames of a real LIGGGHTS hopper discharge (docs/examples/data): 50 um
spheres leaving a cone through its outlet at z = 0. Writes ``hopper-velocity.png`` and
``hopper.vti`` (for ParaView) in the current directory.
"""

from pathlib import Path

from pygran_core import analysis

DATA = Path(__file__).parent / "data" / "liggghts-hopper"
hopper = analysis.System(Particles=str(DATA / "particles*.dump"))

# rings about the hopper's axis (z, through x = y = 0): 10 radial x 20 axial cells
grid = analysis.GridCylindrical(axis="z", bins=(10, 20), range=((0, 1e-3), (-1e-3, 3e-3)))
cg = analysis.CoarseGrain(hopper, grid=grid, kernel="lucy", width=1e-4, density=2500)
fields = cg.compute(frames=slice(0, 3))  # all three frames
print(fields)

r, z = fields.coordinates
speed = -fields.velocity[..., 2]  # downwards, m/s
density = fields.density
print(f"mass in the grid: {fields.mass * 1e9:.2f} ug (particles: 3 frames averaged)")
full = density > 0.3 * density.max()
print(f"bulk density up to {density.max():.0f} kg/m^3")
print(f"downward speed {speed[full].min():.3f} to {speed[full].max():.3f} m/s")
axis = speed[0, (z > 0) & (z < 1e-3)].mean()
wall = speed[6, (z > 1.5e-3) & (z < 2.5e-3)].mean()
print(
    f"near the axis just above the outlet {axis:.3f} m/s, higher up at r = {r[6] * 1e3:.2f} mm {wall:.3f} m/s"
)

fields.plot("density", quiver=True, cmap="viridis", path="hopper-velocity.png")
fields.to_vtk("hopper.vti")
print("wrote hopper-velocity.png and hopper.vti")
