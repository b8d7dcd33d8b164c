"""The native solver's clumps: rigid bodies of overlapping spheres (see
:class:`pygran_native.solver.Solver` and _clumps.pxi)."""

from __future__ import annotations

import math

import numpy as np

from pygran_core.errors import ConfigError
from pygran_core.simulation import clumps
from pygran_native.arguments import array_of, per_particle
from pygran_native.base import SolverBase


class Bodies(SolverBase):
    """A solver's clumps: a part of :class:`~pygran_native.solver.Solver`."""

    def add_clumps(
        self, spheres, positions, density: float, orientations=None, types=0, velocities=None, omegas=None
    ) -> np.ndarray:
        """Add rigid clumps of the template ``spheres`` (rows ``x, y, z, r`` in the clump's own
        frame) of ``density``: the template's origin at each of ``positions``, turned by
        ``orientations`` (unit quaternions ``w, x, y, z``; default: as the template), moving at
        ``velocities`` (of the centre of mass) and ``omegas``. Returns the clumps' ids; their
        spheres' ids follow each other, clump by clump (see :attr:`bodies`)."""
        x = array_of(positions, "positions", (-1, 3))
        n = x.shape[0]
        if not (math.isfinite(density) and density > 0):
            raise ConfigError(f"density: must be > 0, got {density!r}.")
        try:
            props = clumps.mass_properties(array_of(spheres, "spheres", (-1, 4)), density)
        except ValueError as exc:
            raise ConfigError(f"spheres: {exc}.") from None
        template = np.asarray(spheres, float)
        q = (
            np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
            if orientations is None
            else array_of(orientations, "orientations", (n, 4))
        )
        if np.any(np.abs(np.linalg.norm(q, axis=1) - 1) > 1e-9):
            raise ConfigError("orientations: quaternions must have length 1.")
        t = per_particle(types, "types", n, np.int32)
        self._check_types(t, "types")
        v = np.zeros((n, 3)) if velocities is None else array_of(velocities, "velocities", (n, 3))
        w = np.zeros((n, 3)) if omegas is None else array_of(omegas, "omegas", (n, 3))
        turn = clumps.rotation_matrix(q)  # template frame -> world
        axes = turn @ props.axes  # principal frame -> world
        centres = x + turn @ props.centre
        offsets = (template[:, :3] - props.centre) @ props.axes  # principal frame
        k = len(template)
        self._check_inside((centres[:, None] + offsets @ np.swapaxes(axes, 1, 2)).reshape(-1, 3), "positions")
        momenta = props.moments * np.einsum("nji,nj->ni", axes, w)
        bodies = np.arange(self._next_body, self._next_body + n, dtype=np.int64)
        ids = np.arange(self._next_id, self._next_id + n * k, dtype=np.int64)
        self._core.add_bodies(
            np.ascontiguousarray(centres),
            v,
            np.ascontiguousarray(clumps.quaternion_of(axes)),
            np.ascontiguousarray(momenta),
            np.full(n, props.mass),
            np.ascontiguousarray(np.tile(props.moments, (n, 1))),
            t,
            bodies,
            np.full(n, k, np.int32),
            np.ascontiguousarray(np.tile(offsets, (n, 1))),
            np.ascontiguousarray(np.tile(template[:, 3], n)),
            ids,
        )
        self._next_id += n * k
        self._next_body += n
        return bodies.copy()

    def clumps(self) -> dict[str, np.ndarray]:
        """The clumps now, by id: ``id``, ``mass``, ``centre``, ``velocity``, angular velocity
        ``omega`` and ``angular_momentum`` (world frame), ``orientation`` (unit quaternion ``w,
        x, y, z`` of the principal axes), ``inertia`` tensor about the centre (world frame),
        ``force`` and ``torque`` about the centre at the last step."""
        found = self._core.bodies()
        order = np.argsort(found["id"], kind="stable")
        axes = clumps.rotation_matrix(found["q"][order])
        inertia = found["inertia"][order]
        momentum = np.einsum("nij,nj->ni", axes, found["p"][order])
        return {
            "id": found["id"][order],
            "mass": found["m"][order],
            "centre": found["x"][order],
            "velocity": found["v"][order],
            "omega": np.einsum("nij,nj->ni", axes, found["p"][order] / inertia),
            "angular_momentum": momentum,
            "orientation": found["q"][order],
            "inertia": np.einsum("nij,nj,nkj->nik", axes, inertia, axes),
            "force": found["f"][order],
            "torque": found["t"][order],
        }
