"""Manual Listing 3.3: Thornton-Ning coefficient of restitution against the yield pressure.

Each impact is integrated at the characteristic velocity; the restitution is read from
the overlap rate at the end of contact, as in the manual. Thornton's (1997) analytic
elastic-plastic relation is drawn for comparison. Run as
``python contact_restitution_yield.py [output_dir]``; writes
``contact_restitution_yield.png`` (Figure 3.2).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
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


def thornton(model: simulation.models.ThorntonNing, velocity: float) -> float:
    """Thornton (1997) eq. (30) at the impact ``velocity``, with the model's yield velocity."""
    if velocity <= model.yieldVel:
        return 1.0
    r = model.yieldVel / velocity
    return np.sqrt(6 * np.sqrt(3) / 5 * (1 - r**2 / 6)) * (r / (r + 2 * np.sqrt(6 / 5 - r**2 / 5))) ** 0.25


def compute() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yield pressures (Pa), simulated and analytic coefficients of restitution."""
    pressure = np.arange(1e6, 4e6, 1e5)
    COR, analytic = [], []
    for yieldPress in pressure:
        model = simulation.models.ThorntonNing(material=dict(powderX, yieldPress=yieldPress))
        time, disp, force = model.displacement()
        deltav = disp[:, 1]
        COR.append(abs(deltav[-1] / deltav[0]))
        analytic.append(thornton(model, powderX["characteristicVelocity"]))
    return pressure, np.array(COR), np.array(analytic)


def main(argv: list[str]) -> Path:
    output = Path(argv[0] if argv else ".") / "contact_restitution_yield.png"
    pressure, COR, analytic = compute()
    fig = Figure(figsize=(5, 4), layout="tight")
    ax = fig.add_subplot()
    ax.plot(pressure / 1e6, COR, "o", label="ThorntonNing.displacement()")
    ax.plot(pressure / 1e6, analytic, "-", label="Thornton (1997), analytic")
    ax.set(
        xlabel="yield pressure (MPa)",
        ylabel="coefficient of restitution",
        title="Particle-wall impact at 0.1 m/s, R* = 100 um",
    )
    ax.legend()
    fig.savefig(output, dpi=120)
    return output


if __name__ == "__main__":
    print(main(sys.argv[1:]))
