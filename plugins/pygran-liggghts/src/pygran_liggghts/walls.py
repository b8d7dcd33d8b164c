"""The walls of a simulation on LIGGGHTS: a ``fix wall/gran`` per primitive wall, all mesh walls
in the one ``fix wall/gran`` LIGGGHTS allows (replaced as they change), the meshes' motions,
the force on a mesh, and the numbers by which contact records name the mesh walls.
"""

from __future__ import annotations

import numpy as np

from pygran_core.errors import ConfigError, UnsupportedFeature
from pygran_core.simulation.calls import MotionSpec, WallSpec
from pygran_core.simulation.specs import SimulationSpec, given
from pygran_liggghts.channel import Channel
from pygran_liggghts.commands import Commands


class Walls:
    """The walls and mesh motions of one simulation, by label; ``channel`` runs their commands."""

    def __init__(self, spec: SimulationSpec, commands: Commands, channel: Channel) -> None:
        self._spec = spec
        self._commands = commands
        self._channel = channel
        self.meshes: dict[str, str] = {}  # label -> the mesh of each mesh wall, in the order added
        self.motions: dict[str, str] = {}  # label -> the moving mesh
        self._fix: str | None = None  # the one fix wall/gran of all mesh walls
        self._numbers: dict[str, int] = {}  # label -> k: the k-th wall set up
        #: Whether LIGGGHTS writes the mesh walls' contacts (traj cfile); ``None``: until the
        #: first run, which defines its contact computes
        self._contacts: bool | None = None

    def add(self, spec: WallSpec) -> str:
        """Set wall ``spec`` up; its label."""
        if spec.kind == "mesh" and spec.mesh in self.meshes.values():
            raise ConfigError(f"mesh {spec.mesh!r} is already a wall; remove that wall first")
        if self._spec.traj.cfile is not None and (spec.kind != "mesh" or self._contacts is False):
            raise UnsupportedFeature(
                "LIGGGHTS writes the contacts (traj cfile) with mesh walls set up before the first run only "
                "(its compute wall/gran/local takes mesh walls and is defined before the first run): "
                + (
                    "make this wall a mesh (setupWall(wtype='mesh', ...))"
                    if spec.kind != "mesh"
                    else "set this mesh wall up before the first run"
                )
                + ", or drop traj cfile"
            )
        label, lines = self._commands.wall(spec)
        self._numbers[label] = len(self._numbers)
        if spec.kind == "mesh":
            self.meshes[label] = given(spec.mesh, "a mesh wall's mesh")
            lines = self._rebuild()
        self._channel.execute(lines)
        return label

    def move(self, spec: MotionSpec, waiting: list[str]) -> str:
        """Move a mesh by motion ``spec``; its label. ``waiting``: the insertions PyGran places
        clear of that mesh (see :mod:`.placings`) with events to come, which refuse it."""
        if any(mesh.servo for mesh in self._spec.meshes if mesh.name == spec.mesh):
            raise ConfigError(
                f"mesh {spec.mesh!r} is a servo wall, which its controller moves: LIGGGHTS cannot "
                "move it with moveMesh too"
            )
        if waiting:
            raise ConfigError(
                f"moveMesh({spec.mesh!r}) while the insertion {waiting[0]}, into a region the mesh crosses, "
                "has events to come: PyGran places its particles clear of the mesh where it stands, "
                "and a moving mesh's position is LIGGGHTS'. Remove that insertion first, or insert "
                "into a region clear of the mesh"
            )
        label, lines = self._commands.motion(spec)
        self._channel.execute(lines)
        self.motions[label] = spec.mesh
        return label

    def remove(self, label: str) -> None:
        """Remove the wall, motion or other fix ``label`` from LIGGGHTS."""
        self.motions.pop(label, None)
        if self.meshes.pop(label, None) is not None:
            self._channel.execute(self._rebuild())
        else:
            self._channel.execute([f"unfix {label}"])

    def force(self, name: str) -> np.ndarray:
        """The force (N, x y z) the particles exert on mesh ``name`` now, as LIGGGHTS sums it
        over the mesh (``mtype`` ``mesh/surface/stress`` or ``mesh/surface/stress/servo``)."""
        mesh = next((m for m in self._spec.meshes if m.name == name), None)
        if mesh is None or mesh.mtype == "mesh/surface":
            stress = [m.name for m in self._spec.meshes if m.mtype != "mesh/surface"]
            raise ConfigError(
                f"mesh_force({name!r}): LIGGGHTS sums the force on meshes of mtype mesh/surface/stress or "
                f"mesh/surface/stress/servo; such meshes here: {stress or 'none'}"
            )
        return np.array(self._channel.request("fix_vector", self._commands.mesh_ids[name], 3))

    def contact_computes(self) -> list[str]:
        """Before the first run, with ``traj cfile``: the compute of the mesh walls' contacts
        (LIGGGHTS defines its contact computes before the first run only), if there are any."""
        if self._spec.traj.cfile is None or self._contacts is not None:
            return []
        self._contacts = bool(self.meshes)
        return self._commands.contacts("pg_walls") if self._contacts else []

    def contact_numbers(self) -> list[int]:
        """The number k (the k-th wall set up) of each mesh wall, by LIGGGHTS' mesh index."""
        return [self._numbers[label] for label in self.meshes]

    def _rebuild(self) -> list[str]:
        """Lines replacing the fix of the mesh walls by one with the current ones (LIGGGHTS
        allows one such fix; contacts with meshes start afresh, without tangential history)."""
        lines = [] if self._fix is None else [f"unfix {self._fix}"]
        self._fix = None
        if self.meshes:
            self._fix, fix = self._commands.mesh_walls(list(self.meshes.values()))
            lines += fix
        return lines
