"""Manual Listing 3.4: force-displacement and displacement-time of a cohesive impact.

The manual's cohesive elastic-plastic powder (Thornton-Ning with JKR adhesion, surface
energy 0.04 J/m^2) hits a wall of the same material at its characteristic velocity
(0.04 m/s): it is captured, and the curve runs until it turns back towards the wall.
A faster impact (0.4 m/s) that breaks free is drawn for comparison. Run as
``python contact_cohesive.py [output_dir]``; writes ``contact_cohesive.png``
(Figure 3.3 a and b).
"""

from __future__ import annotations

import sys
from pathlib import Path

from matplotlib.figure import Figure  # renders with Agg; pyplot's global state is not used

from pygran_core import simulation

# Define powder properties with cohesion
powder = {
    "radius": 2e-5,
    "yieldPress": 4e7,
    "density": 1500.0,
    "youngsModulus": 6e9,
    "cohesionEnergyDensity": 0.04,
    "poissonsRatio": 0.25,
    "characteristicVelocity": 0.04,
}

VELOCITIES = (None, 0.4)  # None: the characteristic velocity, as in the manual


def compute() -> dict:
    """Impacts by velocity (m/s); unpack each as ``time, delta, force``."""
    model = simulation.models.ThorntonNing(material=powder)
    return {
        velocity or powder["characteristicVelocity"]: model.displacement(velocity) for velocity in VELOCITIES
    }


def main(argv: list[str]) -> Path:
    output = Path(argv[0] if argv else ".") / "contact_cohesive.png"
    fig = Figure(figsize=(10, 4), layout="tight")
    force_ax, time_ax = fig.subplots(1, 2)
    for velocity, impact in compute().items():
        time, delta, force = impact
        label = f"{velocity:g} m/s, " + ("captured" if impact.captured else f"e = {impact.restitution:.2f}")
        force_ax.plot(delta[:, 0] * 1e9, force * 1e6, label=label)
        time_ax.plot(time * 1e9, delta[:, 0] * 1e9, label=label)
    force_ax.set(xlabel="normal overlap (nm)", ylabel="normal force (uN)", title="(a) force-displacement")
    time_ax.set(xlabel="time (ns)", ylabel="normal overlap (nm)", title="(b) displacement-time")
    force_ax.axhline(0, color="grey", lw=0.5)
    force_ax.legend()
    fig.savefig(output, dpi=120)
    return output


if __name__ == "__main__":
    print(main(sys.argv[1:]))
