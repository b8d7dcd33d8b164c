"""Manual chapter 6.4: wall meshes as ``System.Mesh``.

Loads the hopper's surface-mesh sequence and, for the first and last frames, prints the
number of cells and points, the total wall area, the cell data read from the files and the
height range of the cell centres. Run as ``python analysis_mesh.py [mesh_glob]`` (default: the shared hopper
fixture).
"""

from __future__ import annotations

import sys
from pathlib import Path

from pygran_core import analysis

HOPPER = Path(__file__).resolve().parents[1] / "tests" / "data" / "liggghts-hopper"


def main(argv: list[str]) -> dict:
    meshes = argv[0] if argv else str(HOPPER / "mesh*.vtk")
    System = analysis.System(Mesh=meshes)
    areas = {}
    for frame in (0, -1):
        System.goto(frame)
        Mesh = System.Mesh
        areas[System.frame] = float(Mesh.computeAreas().sum())
        centres = Mesh.computeCentres()
        print(
            f"frame {System.frame} of {len(System)}: {Mesh.nCells()} cells on {Mesh.nPoints()} points, "
            f"wall area {areas[System.frame]:.4g} m^2, cell data {sorted(Mesh.cell_data)}, "
            f"centres at z = {centres[:, 2].min():.3g} .. {centres[:, 2].max():.3g} m"
        )
    return {"frames": len(System), "areas": areas, "mesh": System.Mesh}


if __name__ == "__main__":
    main(sys.argv[1:])
