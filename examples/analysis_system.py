"""Manual chapters 5 and 6.1: a System over a trajectory, frames, selections and statistics.

Reads the LIGGGHTS hopper run (particles and wall meshes), loops over every frame, selects
particles with the manual's combined boolean selection and computes coordination numbers and
the radial distribution function on the last frame. Run as
``python analysis_system.py [particles_glob] [mesh_glob]`` (defaults: the shared hopper
fixture); prints one line per frame and a summary.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from pygran_core import analysis

HOPPER = Path(__file__).resolve().parents[1] / "tests" / "data" / "liggghts-hopper"


def main(argv: list[str]) -> dict:
    particles = argv[0] if argv else str(HOPPER / "particles*.dump")
    meshes = argv[1] if len(argv) > 1 else str(HOPPER / "mesh*.vtk")
    Granular = analysis.System(Particles=particles, Mesh=meshes, units="si")

    # Frame 0 is read on construction; the loop (the original's) rewinds, then loads each
    # following frame into Granular.Particles / .Mesh and yields its number
    def describe() -> int:
        count = Granular.Particles.natoms
        print(
            f"frame {Granular.frame}: timestep {Granular.timestep}, {count} particles, "
            f"{Granular.Mesh.nCells()} wall cells"
        )
        return count

    counts = [describe()]
    for _frame in Granular:
        counts.append(describe())

    Granular.goto(-1)  # the last frame
    Particles = Granular.Particles

    # static particles along z, or those in a cylinder of height h and radius r about the axis
    h, r = 2e-3, 5e-4
    sel = (Particles.vz != 0) | ((Particles.z <= h) & (Particles.x**2 + Particles.y**2 <= r**2))
    SliceSub = Particles[sel]
    print(f"selected {len(SliceSub)} of {len(Particles)} particles")

    # every element is a length-1 Particles whose attributes can be read but not changed
    radii = [float(particle.radius[0]) for particle in Particles[:5]]

    coon = analysis.equilibrium.Neighbors(Particles).coon
    rdf = Particles.computeRDF()
    print(
        f"mean coordination number {coon.mean():.3f}; RDF maximum {rdf.g.max():.2f} "
        f"at r = {rdf.r[np.argmax(rdf.g)]:.3g} m; radius of gyration {Particles.computeROG():.3g} m"
    )
    return {"counts": counts, "selected": len(SliceSub), "radii": radii, "coon": coon, "rdf": rdf}


if __name__ == "__main__":
    main(sys.argv[1:])
