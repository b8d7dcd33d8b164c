"""Manual Listing 3.2: force-displacement of a spring-dashpot and a Hertz-Mindlin impact.

A particle of radius 100 um hits a wall of the same material at its characteristic
velocity. Run as ``python contact_force_displacement.py [output_dir]``; writes
``contact_force_displacement.png`` (Figure 3.1).
"""

from __future__ import annotations

import sys
from pathlib import Path

from matplotlib.figure import Figure  # renders with Agg; pyplot's global state is not used

from pygran_core import simulation

powderX = {
    "youngsModulus": 1e8,
    "poissonsRatio": 0.25,
    "coefficientRestitution": 0.9,
    "characteristicVelocity": 0.1,
    "density": 997.164,
    "radius": 1e-4,
}


def compute() -> dict:
    """Overlap (m) and normal force (N) of each model's impact, by model name."""
    curves = {}
    for model in (simulation.models.SpringDashpot, simulation.models.HertzMindlin):
        time, soln, force = model(material=powderX).displacement()
        curves[model.__name__] = (soln[:, 0], force)
    return curves


def main(argv: list[str]) -> Path:
    output = Path(argv[0] if argv else ".") / "contact_force_displacement.png"
    fig = Figure(figsize=(5, 4), layout="tight")
    ax = fig.add_subplot()
    for name, (deltan, force) in compute().items():
        ax.plot(deltan * 1e6, force * 1e3, label=name)
    ax.set(xlabel="normal overlap (um)", ylabel="normal force (mN)", title="Particle-wall impact, e = 0.9")
    ax.legend()
    fig.savefig(output, dpi=120)
    return output


if __name__ == "__main__":
    print(main(sys.argv[1:]))
