"""Manual chapter 6.3, "Custom SubSystems": a user-defined coarse-grained Particles class.

``CoarseParticles`` scales the particle radii by ``scale`` and then drops the particles that
overlap a neighbour by more than ``percent`` % of their radius. ``System`` creates it by name;
``module=`` tells it where the class lives: here the name of this script's module (a path
to the ``.py`` file or the module object work too). Run as
``python analysis_coarse_grained.py [traj.dump] [CG.dump]``; by default the last frame of
the hopper run (the first has no particles) is coarse-grained and written to ``CG.dump``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pygran_core import analysis

HOPPER = Path(__file__).resolve().parents[1] / "tests" / "data" / "liggghts-hopper"


class CoarseParticles(analysis.Particles):
    def __init__(self, **args):
        scale, percent = args.pop("scale", None), args.pop("percent", None)
        super().__init__(**args)

        if scale is not None and percent is not None:
            self.scale(scale, ("radius",))
            CG = analysis.equilibrium.Neighbors(self).filter(percent=percent)
            self.__init__(CoarseParticles=CG)


def main(argv: list[str]) -> analysis.Particles:
    traj = argv[0] if argv else str(HOPPER / "particles*.dump")
    output = argv[1] if len(argv) > 1 else "CG.dump"
    Traj = analysis.System(CoarseParticles=traj, scale=3, percent=10.0, module="analysis_coarse_grained")
    Traj.goto(-1)
    Traj.CoarseParticles.write(output)
    print(f"{len(Traj.CoarseParticles)} coarse-grained particles written to {output}")
    return Traj.CoarseParticles


if __name__ == "__main__":
    main(sys.argv[1:])
