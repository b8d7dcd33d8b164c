"""Use the example plugin after ``pip install ./docs/examples/pygran-example``."""

from pathlib import Path

import numpy as np

from pygran_core import analysis, params, registry, simulation

# The three items are registered next to the built-in ones.
print("engines:", sorted(registry.available("engine")))
print("models:", sorted(registry.available("model")))
print("readers:", sorted(registry.available("reader")))

# The engine: selected by name, driven through the engine-neutral front end. It declares no
# "rolling-friction" capability, so a material with rolling friction would be refused with
# UnsupportedFeature before anything runs: steel here has it switched off.
with simulation.DEM(
    engine="ballistic",
    box=(-1, 1, -1, 1, 0, 2),
    gravity=(9.81, 0, 0, -1),
    dt=1e-3,
    output="ballistic-out",
    species=({"material": dict(params.steel, coefficientRollingFriction=0.0), "radius": 0.01},),
    traj={"freq": 100, "pfile": None},  # no trajectory file
) as sim:
    sim.createParticles(1, "single", 0.0, 0.0, 1.0, vel=(1.0, 0.0, 2.0))
    sim.run(400)  # 0.4 s
    x = sim.extractCoords()[0]
    print(f"after {sim.time:.1f} s the sphere is at x = {x[0]:.3f} m, z = {x[2]:.4f} m")
    assert np.allclose(x, (0.4, 0.0, 1.0 + 2.0 * 0.4 - 0.5 * 9.81 * 0.4**2))

# The model: looked up by name; it is a full reference model (impacts, restitution).
Stiff = registry.get_model("StiffSpringDashpot").model
material = dict(params.glass, radius=1e-3)
stiff, plain = Stiff(material=material), simulation.models.SpringDashpot(material=material)
print(
    f"contact time {stiff.contactTime():.2e} s (plain hooke {plain.contactTime():.2e} s), "
    f"restitution {stiff.restitution():.3f}"
)

# The reader: any *.xyz file now opens in analysis.System, pygran info and pygran convert.
Path("two-frames.xyz").write_text("2\nframe 0\nC 0 0 0\nC 1 0 0\n2\nframe 1\nC 0 0 1\nC 1 0 1\n")
system = analysis.System(Particles="two-frames.xyz")
system.goto(-1)
print(f"{len(system)} frames; last frame z = {system.Particles.z}")
