"""The first simulation: glass beads poured onto a floor, then analysed.

Runs in a few seconds on the native engine (``pip install ./plugins/pygran-native``) and
writes ``out/`` in the current directory: ``traj.h5`` (H5MD trajectory), ``energy.txt``
(monitor) and ``pygran.log`` (every call the script made).
"""

from pygran_core import analysis, params, simulation

# Glass beads of radius 0.5 mm, softened to E = 10 MPa (common DEM practice: a softer
# material allows a larger time step) and made more dissipative so that they settle fast.
beads = dict(params.glass, youngsModulus=1e7, coefficientRestitution=0.5)
radius = 5e-4

# The reference contact model gives the duration of an impact; resolve it with 25 steps.
model = simulation.models.HertzMindlin(material=dict(beads, radius=radius))
dt = model.contactTime() / 25
print(f"contact time {model.contactTime():.2e} s, time step {dt:.2e} s")

with simulation.DEM(
    engine="native",
    model=simulation.models.HertzMindlin,
    box=(-3e-3, 3e-3, -3e-3, 3e-3, 0, 1.5e-2),  # xmin, xmax, ymin, ymax, zmin, zmax (m)
    boundary=("p", "p", "f"),  # periodic in x and y
    gravity=(9.81, 0, 0, -1),  # magnitude, then direction
    dt=dt,
    output="out",
    species=({"material": beads, "radius": radius},),
    traj={"freq": 2000, "pfile": "traj.h5"},  # the extension picks the format
) as sim:
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    fill = sim.insert(species=1, value=100, region=("block", -3e-3, 3e-3, -3e-3, 3e-3, 1e-3, 1.5e-2))
    energy = sim.monitor(quantities=("ke", "n"), freq=1000, file="energy.txt")
    sim.run(20000)  # 20000 steps of dt
    sim.remove(fill)

    x, v = sim.extractCoords(), sim.extractVelocities()  # (N, 3) arrays, ordered by id
    print(f"{len(x)} particles at t = {sim.time:.3f} s; top of the bed at z = {x[:, 2].max() * 1e3:.1f} mm")
    ke = energy.values["ke"]  # one entry per sample, as are energy.values["step"], ["n"]
    print(f"kinetic energy: {ke[1]:.1e} J at step 1000, {ke[-1]:.1e} J at the end")

# The trajectory is an ordinary H5MD file: analyse it like any other.
bed = analysis.System(Particles="out/traj.h5")
bed.goto(-1)
P = bed.Particles
coordination = analysis.equilibrium.Neighbors(P).coon
print(f"{len(bed)} frames; mean coordination number {coordination.mean():.2f}")
