"""Manual chapters 5 and 6.2-6.3: building SubSystems, copying, slicing and binary operators.

``SubSystem(**input_data)`` builds an object from a dictionary of arrays,
``SubSystem(SubSystem=other)`` copies one; ``+=`` appends, ``+`` concatenates over the common
attributes and ``*`` yields the geometric means of every pair of elements
(``Particles_i + Particles_j * Particles_k`` has ``n_i + n_j n_k`` particles). Run as
``python analysis_subsystem.py [particles.dump] [output.dump]``: takes the last frame of
the hopper run by default and writes the combined particles to ``output.dump``
(default ``combined.dump``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from pygran_core import analysis

HOPPER = Path(__file__).resolve().parents[1] / "tests" / "data" / "liggghts-hopper"


def main(argv: list[str]) -> dict:
    source = argv[0] if argv else str(HOPPER / "particles30000.dump")
    output = Path(argv[1] if len(argv) > 1 else "combined.dump")
    Particles = analysis.System(Particles=source).Particles

    # a new SubSystem from a dictionary, and a copy of it
    input_data = {"x": np.array([0.0, 1e-4]), "y": np.zeros(2), "z": np.zeros(2), "radius": np.full(2, 5e-5)}
    NewSS = analysis.SubSystem(**input_data)
    CopySS = analysis.SubSystem(SubSystem=NewSS)

    # slicing by int, slice, int array and boolean mask returns the same class
    Particles_i = Particles[Particles.radius >= Particles.radius.mean()][:10]
    Particles_j = Particles[np.arange(3)]
    Particles_k = Particles[3:5]

    Extended = Particles_i.copy()
    Extended += Particles_j  # appended; Particles_j has every attribute Particles_i has
    Combined = Particles_i + Particles_j * Particles_k
    print(f"{len(Particles_i)} + {len(Particles_j)} x {len(Particles_k)} -> {len(Combined)} particles")
    Combined.write(output)
    return {"new": NewSS, "copy": CopySS, "extended": Extended, "combined": Combined, "output": output}


if __name__ == "__main__":
    main(sys.argv[1:])
