"""The native solver's walls: planes, cylinders and triangle meshes, the meshes' motion and
vibration, and stress and servo meshes (see :class:`pygran_native.solver.Solver`)."""

from __future__ import annotations

import math

import numpy as np

from pygran_core.errors import ConfigError
from pygran_native._solver import (
    HARMONICS,
    SLOT_LAYOUT,
    SLOT_VALUES,
    VIBRATION_LAYOUT,
    VIBRATION_VALUES,
)
from pygran_native.arguments import array_of, layout
from pygran_native.base import SolverBase

#: Where a stress mesh's values lie in its row of ``Core.get_slots()``, and a vibrating mesh's
#: in its row of ``Core.get_vibrations()`` (the layouts _solver.pyx declares).
SLOT = layout(SLOT_LAYOUT)
VIBRATION = layout(VIBRATION_LAYOUT)
#: What a stress mesh's CONTROL value says: its force is summed, or it is a servo on the force
#: along its axis or on the torque about it.
CONTROLS = ("stress", "force", "torque")
#: Vibrations (LIGGGHTS move/mesh viblin, vibrot): their kinds.
VIBRATIONS = ("viblin", "vibrot")
#: The kinds of walls, as a checkpoint numbers them.
WALL_KINDS = ("plane", "cylinder", "mesh")


class Walls(SolverBase):
    """The walls of a solver and their motion: a part of :class:`~pygran_native.solver.Solver`."""

    def _add_wall(self, kind: str, kinds, wtype, geo, vid) -> int:
        wtype = int(wtype) if np.ndim(wtype) == 0 and float(wtype).is_integer() else None
        if wtype is None:
            raise ConfigError("type: a wall's type must be an integer.")
        self._check_types(np.array([wtype]), "type")
        handle = self._next_wall
        k = len(kinds)
        self._core.add_elements(
            np.asarray(kinds, np.int32),
            np.full(k, wtype, np.int32),
            np.full(k, handle, np.int32),
            np.ascontiguousarray(geo, float),
            np.ascontiguousarray(vid, np.int32),
        )
        self._next_wall += 1
        self._walls[handle] = kind
        return handle

    def add_plane(self, point, normal, type: int = 0) -> int:
        """Two-sided plane through ``point``; ``normal`` only breaks the tie of a contact that
        begins with the centre exactly on the plane (see the module docstring)."""
        p = array_of(point, "point", (3,))
        nrm = array_of(normal, "normal", (3,))
        length = np.linalg.norm(nrm)
        if length == 0:
            raise ConfigError("normal: must not be zero.")
        geo = np.concatenate([p, nrm / length, np.zeros(3)])[None]
        return self._add_wall("plane", [0], type, geo, np.full((1, 3), -1))

    def add_cylinder(self, axis: str, centre, radius: float, type: int = 0, inside: bool = True) -> int:
        """Infinite cylinder along ``axis`` through ``centre`` (the two other coordinates)."""
        if axis not in ("x", "y", "z"):
            raise ConfigError(f"axis: must be 'x', 'y' or 'z', got {axis!r}.")
        c = array_of(centre, "centre", (2,))
        if not (math.isfinite(radius) and radius > 0):
            raise ConfigError(f"radius: must be > 0, got {radius!r}.")
        geo = np.array([[float("xyz".index(axis)), c[0], c[1], radius, 1.0 if inside else 0.0, 0, 0, 0, 0]])
        return self._add_wall("cylinder", [1], type, geo, np.full((1, 3), -1))

    def add_mesh(self, vertices, triangles, type: int = 0) -> int:
        """Triangle-mesh wall; duplicate vertices are merged and zero-area triangles dropped."""
        verts = array_of(vertices, "vertices", (-1, 3))
        tris = array_of(triangles, "triangles", (-1, 3), np.int64)
        if tris.size and (tris.min() < 0 or tris.max() >= len(verts)):
            raise ConfigError(f"triangles: vertex indices must lie in [0, {len(verts) - 1}].")
        unique, inverse = np.unique(verts, axis=0, return_inverse=True)
        vid = inverse.reshape(-1)[tris]
        corners = unique[vid]
        area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        keep = area > 0
        if not np.any(keep):
            raise ConfigError("triangles: the mesh has no triangle of non-zero area.")
        vid, corners = vid[keep], corners[keep]
        handle = self._add_wall(
            "mesh", np.full(len(vid), 2), type, corners.reshape(-1, 9), vid + self._next_vertex
        )
        self._next_vertex += len(unique)
        return handle

    def set_mesh_motion(
        self,
        mesh: int,
        velocity=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        origin=(0.0, 0.0, 0.0),
        amplitude=(0.0, 0.0, 0.0),
        period: float | None = None,
    ) -> None:
        """Rigid motion of a mesh from now on (time ``t0``), replacing any earlier one.

        Translation at ``velocity``, a wiggle of ``amplitude`` (a vector) and ``period``
        (LIGGGHTS ``move/mesh wiggle``: displacement ``A sin(2 pi (t - t0) / T)``, velocity
        ``A (2 pi / T) cos(2 pi (t - t0) / T)``), and rotation at ``angular_velocity``
        (rad/s, a vector) about ``origin``, which follows the translation and the wiggle.
        Positions come from the closed form at every step, so nothing drifts. With no
        arguments the mesh stops.
        """
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        slot = self._slot(mesh)
        if slot is not None and slot[SLOT.CONTROL] != 0:
            raise ConfigError(f"mesh: {mesh!r} is a servo wall, which its controller moves.")
        amplitude = array_of(amplitude, "amplitude", (3,))
        if period is not None and not (math.isfinite(period) and period > 0):
            raise ConfigError(f"period: must be > 0, got {period!r}.")
        if np.any(amplitude != 0) and period is None:
            raise ConfigError("period: a wiggle amplitude needs a period.")
        self._set_vibration(mesh, None)
        self._core.set_motion(
            mesh,
            array_of(velocity, "velocity", (3,)),
            array_of(angular_velocity, "angular_velocity", (3,)),
            array_of(origin, "origin", (3,)),
            amplitude,
            0.0 if period is None or not np.any(amplitude != 0) else float(period),
        )

    def _slot(self, mesh: int) -> np.ndarray | None:
        """The stress values of a mesh (see _S), None if its force is not summed."""
        rows = [row for row in self._core.get_slots() if row[SLOT.WALL] == mesh]
        return rows[0] if rows else None

    def _put_slot(self, row: np.ndarray) -> None:
        slots = [r for r in self._core.get_slots() if r[SLOT.WALL] != row[SLOT.WALL]]
        self._core.set_slots(np.ascontiguousarray(np.reshape([*slots, row], (-1, SLOT_VALUES))))

    def set_stress(self, mesh: int, reference=(0.0, 0.0, 0.0)) -> None:
        """Sum the force of the particles on a mesh, and their torque about ``reference``, at
        every step (LIGGGHTS ``mesh/surface/stress``): :meth:`mesh_force`."""
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        if self._slot(mesh) is not None:
            raise ConfigError(f"mesh: the force on mesh {mesh!r} is summed already.")
        row = np.zeros(SLOT_VALUES)
        row[SLOT.WALL] = mesh
        row[SLOT.COM] = row[SLOT.COM0] = array_of(reference, "reference", (3,))
        row[SLOT.ARM] = 1.0
        self._put_slot(row)

    def set_servo(
        self,
        mesh: int,
        *,
        control: str,
        axis,
        target: float,
        vel_max: float,
        com,
        kp: float = 0.01,
        ki: float = 0.0,
        kd: float = 0.0,
        mode: str = "pid",
        ratio: float | None = None,
    ) -> None:
        """Make a mesh a servo wall (LIGGGHTS ``mesh/surface/stress/servo``): it moves along
        the unit ``axis`` (``control='force'``) or turns about it through ``com``
        (``'torque'``) so that the particles' force (N), or torque about ``com`` (N m), along
        the axis comes to ``target``, at up to ``vel_max`` m/s (at its farthest vertex from
        the axis when turning). The controller is LIGGGHTS': PID with gains ``kp, ki, kd``
        (mode ``'pid'``) or ``mode='auto'``, at ``ratio`` r_min / dt in contact. Its force and
        state: :meth:`mesh_force`, :meth:`servo_state`."""
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        if self._slot(mesh) is not None:
            raise ConfigError(f"mesh: mesh {mesh!r} is a stress or servo mesh already.")
        if control not in ("force", "torque"):
            raise ConfigError(f"control: 'force' or 'torque', got {control!r}.")
        if mode not in ("pid", "auto"):
            raise ConfigError(f"mode: 'pid' or 'auto', got {mode!r}.")
        direction = array_of(axis, "axis", (3,))
        length = float(np.linalg.norm(direction))
        if length == 0:
            raise ConfigError("axis: must not be zero.")
        direction = direction / length
        centre = array_of(com, "com", (3,))
        for name, value in (("target", target), ("vel_max", vel_max), ("kp", kp), ("ki", ki), ("kd", kd)):
            if not math.isfinite(value):
                raise ConfigError(f"{name}: must be finite, got {value!r}.")
        if target == 0:
            raise ConfigError("target: the servo's force or torque must not be 0.")
        if not vel_max > 0:
            raise ConfigError(f"vel_max: must be > 0, got {vel_max!r}.")
        if mode == "auto" and not (ratio is not None and math.isfinite(ratio) and ratio > 0):
            raise ConfigError(f"ratio: mode 'auto' needs a ratio > 0, got {ratio!r}.")
        if mode == "pid" and (min(kp, ki, kd) < 0 or kp == ki == kd == 0):
            raise ConfigError(f"kp, ki, kd: must be >= 0, not all 0; got {kp!r}, {ki!r}, {kd!r}.")
        arm = 1.0
        if control == "torque":  # LIGGGHTS: the farthest vertex from the axis sets the top speed
            corners = self.mesh_triangles(mesh).reshape(-1, 3)
            arm = float(np.linalg.norm(np.cross(direction, corners - centre), axis=1).max())
            if arm == 0:
                raise ConfigError("com, axis: every vertex of the mesh lies on the servo's axis.")
        row = np.zeros(SLOT_VALUES)
        row[SLOT.WALL] = mesh
        row[SLOT.CONTROL] = CONTROLS.index(control)
        row[SLOT.AUTO] = mode == "auto"
        row[SLOT.SET_POINT] = -target  # LIGGGHTS: the particles' force acts against the push
        row[SLOT.VEL_MAX] = vel_max
        row[SLOT.KP], row[SLOT.KI], row[SLOT.KD] = kp, ki, kd
        row[SLOT.RATIO] = ratio or 0.0
        row[SLOT.ARM] = arm
        row[SLOT.OUTPUT_MAX] = vel_max / arm
        row[SLOT.AXIS] = direction
        row[SLOT.COM] = row[SLOT.COM0] = centre
        self._put_slot(row)

    def mesh_force(self, mesh: int) -> tuple[np.ndarray, np.ndarray]:
        """The particles' force (N) on a stress or servo mesh at the last step, and their
        torque (N m) about its reference point (a servo's com)."""
        row = self._slot(mesh)
        if row is None:
            raise ConfigError(f"mesh: {mesh!r} is not a stress or servo mesh of this solver (set_stress).")
        return row[SLOT.FORCE].copy(), row[SLOT.TORQUE].copy()

    def servo_state(self, mesh: int) -> dict[str, float | np.ndarray]:
        """A servo's controller: its ``com`` (m), turned ``angle`` (rad), output ``velocity``
        (m/s or rad/s, a vector), error ``integral`` and ``previous`` process value."""
        row = self._slot(mesh)
        if row is None or row[SLOT.CONTROL] == 0:
            raise ConfigError(f"mesh: {mesh!r} is not a servo mesh of this solver (set_servo).")
        return {
            "com": row[SLOT.COM].copy(),
            "angle": float(row[SLOT.ANGLE]),
            "velocity": row[SLOT.VELOCITY].copy(),
            "integral": float(row[SLOT.INTEGRAL]),
            "previous": float(row[SLOT.PREVIOUS]),
        }

    def set_mesh_vibration(
        self, mesh: int, kind: str, axis, amplitudes, phases, periods, origin=(0.0, 0.0, 0.0)
    ) -> None:
        """Vibration of a mesh from now on (time ``t0``), replacing any earlier motion: LIGGGHTS'
        ``move/mesh viblin`` (``kind='viblin'``, along the unit ``axis``) or ``vibrot`` (about
        ``axis`` through ``origin``) of order ``n = len(amplitudes)``: velocity (m/s, or angular
        velocity in rad/s) ``-sum_j A_j w_j sin(w_j (t - t0) + phi_j)``, ``w_j = 2 pi / T_j``,
        with amplitudes ``A_j`` (m or rad), ``phases`` ``phi_j`` (rad) and ``periods`` ``T_j``
        (s). Positions come from the closed form ``sum_j A_j (cos(w_j (t - t0) + phi_j) -
        cos(phi_j))``, so nothing drifts."""
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        if kind not in VIBRATIONS:
            raise ConfigError(f"kind: 'viblin' or 'vibrot', got {kind!r}.")
        slot = self._slot(mesh)
        if slot is not None and slot[SLOT.CONTROL] != 0:
            raise ConfigError(f"mesh: {mesh!r} is a servo wall, which its controller moves.")
        direction = array_of(axis, "axis", (3,))
        if not np.any(direction != 0):
            raise ConfigError("axis: must not be zero.")
        amp = array_of(np.atleast_1d(amplitudes), "amplitudes", (-1,))
        order = amp.shape[0]
        if not 1 <= order <= HARMONICS:
            raise ConfigError(f"amplitudes: 1 to {HARMONICS} harmonics, got {order}.")
        phase = array_of(np.atleast_1d(phases), "phases", (order,))
        period = array_of(np.atleast_1d(periods), "periods", (order,))
        if np.any(period <= 0):
            raise ConfigError(f"periods: must be > 0, got {period.tolist()}.")
        row = np.zeros(VIBRATION_VALUES)
        row[VIBRATION.WALL], row[VIBRATION.KIND], row[VIBRATION.ORDER] = (
            mesh,
            1 + VIBRATIONS.index(kind),
            order,
        )
        row[VIBRATION.AXIS] = direction / np.linalg.norm(direction)
        row[VIBRATION.AMPLITUDE][:order] = amp
        row[VIBRATION.PHASE][:order] = phase
        row[VIBRATION.FREQUENCY][:order] = 2 * np.pi / period
        zero = np.zeros(3)
        self._set_vibration(mesh, None)
        self._core.set_motion(mesh, zero, zero, array_of(origin, "origin", (3,)), zero, 0.0)
        self._set_vibration(mesh, row)

    def _set_vibration(self, mesh: int, row: np.ndarray | None) -> None:
        """Replace the vibration of a mesh by ``row`` (None: no vibration)."""
        rows = [r for r in self._core.get_vibrations() if r[VIBRATION.WALL] != mesh] + (
            [] if row is None else [row]
        )
        self._core.set_vibrations(np.ascontiguousarray(np.reshape(rows, (-1, VIBRATION_VALUES))))

    def remove_wall(self, wall: int) -> None:
        """Delete a plane, cylinder or mesh (its contact histories go with it)."""
        if wall not in self._walls:
            raise ConfigError(f"wall: {wall!r} is not a wall of this solver.")
        self._core.remove_elements(wall)
        del self._walls[wall]

    remove_mesh = remove_wall

    def walls(self) -> dict[int, str]:
        """Current walls: handle -> ``'plane'``, ``'cylinder'`` or ``'mesh'``."""
        return dict(self._walls)

    def mesh_triangles(self, mesh: int) -> np.ndarray:
        """Current corner coordinates (nt, 3, 3) of a mesh's triangles."""
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        kind, _, wall, geo, _ = self._core.elements()
        return geo[wall == mesh].reshape(-1, 3, 3)

    def _check_servo_speeds(self, dt: float) -> None:
        """Every servo's vel_max below skin / (2 dt), or a ConfigError."""
        for row in self._core.get_slots():
            if row[SLOT.CONTROL] and not row[SLOT.VEL_MAX] < self._core.skin / (2 * dt):
                raise ConfigError(
                    f"vel_max: a servo's {row[SLOT.VEL_MAX]:g} m/s must be below skin / (2 dt) = "
                    f"{self._core.skin / (2 * dt):g} m/s (as LIGGGHTS: it moves at most half the skin "
                    "per step); lower it or dt, or raise the skin."
                )
