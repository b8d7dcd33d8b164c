"""The native DEM solver: argument checking and numpy I/O around the compiled core.

All quantities are SI. Per-particle outputs are copies ordered by particle id. The time
step loop (:meth:`Solver.run`) runs entirely in compiled code without the GIL, on a team of
threads sharing blocks of particles and their contacts (a thread whose core another program
takes leaves its blocks to the others, and waiting threads sleep rather than spin, so a busy
machine slows a run down instead of stalling it); results are bitwise reproducible for a
given thread count, whichever thread runs a block, also across :meth:`Solver.get_state` /
:meth:`Solver.set_state`.

Conventions (LIGGGHTS):

- velocity Verlet for translation and rotation of spheres (moment of inertia
  ``2/5 m r^2``), gravity, viscous force ``F = -gamma v`` per particle type;
- neighbour search: cell list of side ``>= 2 r_max + skin``, half neighbour list rebuilt
  when a particle plus a moving wall have moved more than half the skin since the last
  rebuild; at each rebuild particles are wrapped into periodic directions, sorted by
  cell, and those outside a fixed boundary or non-finite are deleted and counted in
  :attr:`Solver.lost` (LIGGGHTS ``boundary f``), by face and with their speed
  (:meth:`Solver.take_lost`); a non-finite particle forces a rebuild at once;
- contact models: ``hooke``, ``hertz`` and ``thornton-ning`` with the formulas of
  :mod:`pygran_core.simulation.models` (``SpringDashpot``, ``HertzMindlin``,
  ``ThorntonNing``), tangential history with the Coulomb limit, SJKR cohesion for
  hooke/hertz and JKR adhesion for Thornton-Ning when ``cohesion_energy > 0``, rolling
  resistance when ``rolling_friction > 0``: LIGGGHTS' ``cdt`` (its torque's component along
  the contact normal removed, as LIGGGHTS does), ``epsd`` or ``epsd2`` (the last two with a
  spring torque in the contact history); pair values from
  :mod:`pygran_core.simulation.models.mixing`, a wall being a body of infinite radius and
  mass of its own type;
- walls: two-sided planes (LIGGGHTS primitive planes: a contact pushes the particle back
  to the side its centre was on when the contact began, even if a deeply plastic contact
  lets the centre sink past the plane), cylinders (inside or outside), and triangle meshes
  (two-sided; face, edge and vertex contacts, a shared edge or vertex counted once) with
  rigid motion: translation, rotation, wiggle, LIGGGHTS' viblin and vibrot
  (:meth:`Solver.set_mesh_vibration`), or a servo's (LIGGGHTS
  ``mesh/surface/stress/servo``, :meth:`Solver.set_servo`). The particles' force on a stress
  or servo mesh is summed at each step (:meth:`Solver.mesh_force`). Meshes are not repeated
  across periodic boundaries;
- clumps (:meth:`Solver.add_clumps`): rigid bodies of overlapping spheres, with the mass,
  centre and inertia of the union of their spheres
  (:func:`pygran_core.simulation.clumps.mass_properties`). Their spheres are particles in
  every output (each with the clump's mass, its velocity at the sphere's centre and its
  angular velocity; forces and torques: the sphere's contacts), never in contact with one
  another; gravity and viscous drag act on the clump, which is integrated with a quaternion
  and its angular momentum by a symplectic splitting (see _clumps.pxi). A clump one of whose
  spheres leaves a fixed boundary is deleted whole and counted once.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from types import SimpleNamespace

import numpy as np

from pygran_core.errors import ConfigError, ReadError
from pygran_core.simulation import clumps
from pygran_core.simulation.checkpoint import decode_text, encode_text
from pygran_core.simulation.models import mixing
from pygran_native import _kernels
from pygran_native._solver import (
    HARMONICS,
    LOST_PLACES,
    MAX_THREADS,
    MOTION_VALUES,
    SLOT_LAYOUT,
    SLOT_VALUES,
    VIBRATION_LAYOUT,
    VIBRATION_VALUES,
    Core,
)

__all__ = ["Solver", "default_threads"]

_MODELS = {"hooke": 0, "hertz": 1, "thornton-ning": 2}
_HISTORY = {"hooke": 4, "hertz": 4, "thornton-ning": 7}
#: Rolling resistance models (LIGGGHTS ``rolling_friction``); those after cdt keep a spring
#: torque: 3 more history values per contact.
_ROLLING = {"cdt": 0, "epsd": 1, "epsd2": 2}
_WALL_KINDS = ("plane", "cylinder", "mesh")


def _layout(fields: Mapping[str, tuple[int, int]]) -> SimpleNamespace:
    """Indices into a row of values by name: the first value's, or a slice of several."""
    return SimpleNamespace(
        **{k: first if n == 1 else slice(first, first + n) for k, (first, n) in fields.items()}
    )


#: Where a stress mesh's values lie in its row of ``Core.get_slots()``, and a vibrating mesh's
#: in its row of ``Core.get_vibrations()`` (the layouts _solver.pyx declares).
_S = _layout(SLOT_LAYOUT)
_V = _layout(VIBRATION_LAYOUT)


_CONTROLS = ("stress", "force", "torque")
#: Vibrations (LIGGGHTS move/mesh viblin, vibrot): their kinds.
_VIBRATIONS = ("viblin", "vibrot")
#: The contact-model settings a checkpoint stores (the arguments of Solver.set_contact_model).
_MODEL_KEYS = (
    "youngs",
    "poisson",
    "restitution",
    "friction",
    "rolling_friction",
    "rolling_damping",
    "limit_force",
    "cohesion_energy",
    "yield_pressure",
    "characteristic_velocity",
)


def default_threads() -> int:
    """Threads of a solver not told otherwise: ``OMP_NUM_THREADS`` when it is set, else the
    CPUs this process may run on now (``os.sched_getaffinity``: ``taskset``, a batch job's
    cpuset), not every core of the machine."""
    if os.environ.get("OMP_NUM_THREADS"):
        return _kernels.openmp_threads()
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _array(value, name: str, shape: tuple, dtype=float) -> np.ndarray:
    """``value`` as a C-contiguous array of ``shape`` (-1 = any length), or a ConfigError naming it."""
    try:
        arr = np.array(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected numbers, got {value!r}.") from exc
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        want = "x".join("n" if s == -1 else str(s) for s in shape) or "a scalar"
        raise ConfigError(f"{name}: expected shape ({want}), got {arr.shape}.")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: values must be finite.")
    return np.ascontiguousarray(arr)


def _per_particle(value, name: str, n: int, dtype=float) -> np.ndarray:
    arr = np.array(value, dtype=dtype)
    if arr.ndim == 0:
        arr = np.full(n, arr, dtype=dtype)
    return _array(arr, name, (n,), dtype)


def _model_tables(
    kind: str,
    *,
    rolling,
    limit_force,
    restitution,
    yield_pressure,
    characteristic_velocity,
    **per_type_values,
):
    """The arguments of ``Core.set_model`` for a contact model, and the settings as given
    (see :meth:`Solver.set_contact_model`); a ConfigError naming a bad one."""
    if kind not in _MODELS:
        raise ConfigError(f"kind: unknown contact model {kind!r}; choose one of {', '.join(_MODELS)}.")
    if rolling not in _ROLLING:
        raise ConfigError(f"rolling: unknown rolling model {rolling!r}; choose one of {', '.join(_ROLLING)}.")
    if limit_force not in (0, 1):  # True, False, or 1.0, 0.0 from a checkpoint
        raise ConfigError(f"limit_force: must be True or False, got {limit_force!r}.")
    E = _array(np.atleast_1d(per_type_values["youngs"]), "youngs", (-1,))
    nt = E.shape[0]
    if nt == 0:
        raise ConfigError("youngs: give at least one type.")

    def per_type(value, name, check):
        arr = _array(
            np.broadcast_to(np.asarray(value, float), (nt,)) if np.ndim(value) == 0 else value,
            name,
            (nt,),
        )
        if not np.all(check(arr)):
            raise ConfigError(f"{name}: out of range: {arr.tolist()}.")
        return arr

    def pairwise(value, name, check, rule):
        """The (nt, nt) pair matrix ``value`` as given (symmetric), or mixed by ``rule`` from
        per-type values."""
        if np.ndim(value) < 2:
            return mixing.pair_table(rule, per_type(value, name, check))
        arr = _array(value, name, (nt, nt))
        if not np.all(check(arr)) or not np.array_equal(arr, arr.T):
            raise ConfigError(f"{name}: a pair matrix must be symmetric and in range: {arr.tolist()}.")
        return arr

    E = per_type(E, "youngs", lambda a: a > 0)
    nu = per_type(per_type_values["poisson"], "poisson", lambda a: (a > -1) & (a < 0.5))

    def non_negative(name, rule):
        return pairwise(per_type_values[name], name, lambda a: a >= 0, rule)

    mu = non_negative("friction", mixing.pair_friction)
    mur = non_negative("rolling_friction", mixing.pair_friction)
    coh = non_negative("cohesion_energy", mixing.pair_cohesion)
    eta = non_negative("rolling_damping", mixing.pair_friction)  # the smaller one, as LIGGGHTS mixes it
    vchar = 0.0
    if kind == "thornton-ning":
        if yield_pressure is None:
            raise ConfigError("yield_pressure: required by the thornton-ning model.")
        py = per_type(yield_pressure, "yield_pressure", lambda a: a > 0)
        damp = np.zeros((nt, nt))
    else:
        if restitution is None:
            raise ConfigError(f"restitution: required by the {kind} model.")
        e = pairwise(restitution, "restitution", lambda a: (a > 0) & (a <= 1), mixing.pair_restitution)
        py = np.zeros(nt)
        # LIGGGHTS' beta is -zeta
        zeta = np.asarray(mixing.damping_ratio(e), float)
        damp = (2 * math.sqrt(5 / 6) if kind == "hertz" else 2.0) * zeta
        if kind == "hooke":
            if characteristic_velocity is None or not characteristic_velocity > 0:
                raise ConfigError("characteristic_velocity: the hooke model needs a value > 0.")
            vchar = float(characteristic_velocity)
    tables = [
        mixing.pair_table(mixing.effective_modulus, E, nu),
        mixing.pair_table(mixing.effective_shear_modulus, E, nu),
        mu,
        mur,
        np.asarray(damp, float) + np.zeros((nt, nt)),
        coh,
        mixing.pair_table(mixing.pair_yield_pressure, py) if kind == "thornton-ning" else np.zeros((nt, nt)),
        eta,
    ]
    model = {
        "kind": kind,
        "youngs": E,
        "poisson": nu,
        "restitution": restitution,
        "friction": mu,
        "rolling": rolling,
        "rolling_friction": mur,
        "rolling_damping": eta,
        "limit_force": bool(limit_force),
        "cohesion_energy": coh,
        "yield_pressure": yield_pressure,
        "characteristic_velocity": characteristic_velocity,
    }
    history = _HISTORY[kind] + (3 if rolling != "cdt" else 0)
    args = (
        _MODELS[kind],
        history,
        _ROLLING[rolling],
        bool(limit_force),
        *(np.ascontiguousarray(t) for t in tables),
        vchar,
    )
    return args, model


class Solver:
    """A DEM simulation of spheres in a box; see the module docstring for conventions.

    ``box`` is ``[[xlo, ylo, zlo], [xhi, yhi, zhi]]``; ``periodic`` per axis; ``gravity``
    the acceleration vector; ``skin`` the neighbour-list skin; ``threads`` the threads of
    :meth:`run` (default: :func:`default_threads`); ``seed`` seeds :attr:`rng`, the
    solver's random stream (its state is part of :meth:`get_state`).
    """

    def __init__(
        self,
        box,
        periodic=(False, False, False),
        gravity=(0.0, 0.0, 0.0),
        skin: float = 0.0,
        threads: int | None = None,
        seed: int = 0,
    ) -> None:
        box = _array(box, "box", (2, 3))
        if not np.all(box[1] > box[0]):
            raise ConfigError(f"box: every upper bound must exceed the lower one, got {box.tolist()}.")
        periodic = tuple(bool(p) for p in _array(periodic, "periodic", (3,), bool))
        gravity = _array(gravity, "gravity", (3,))
        if not (math.isfinite(skin) and skin > 0):
            raise ConfigError(f"skin: must be > 0, got {skin!r}.")
        threads = default_threads() if threads is None else threads
        if not (isinstance(threads, (int, np.integer)) and 1 <= threads <= MAX_THREADS):
            raise ConfigError(f"threads: must be an integer from 1 to {MAX_THREADS}, got {threads!r}.")
        self.box, self.periodic, self.threads = box, periodic, int(threads)
        self._core = Core(box[0], box[1], periodic, gravity, float(skin), self.threads)
        self.rng = np.random.default_rng(seed)
        self._model: dict | None = None
        self._next_id = 0
        self._next_body = 0
        self._next_wall = 0
        self._next_vertex = 0
        self._walls: dict[int, str] = {}
        self._viscous = np.zeros(0)

    # --- set-up ------------------------------------------------------------------------
    def set_contact_model(
        self,
        kind: str,
        *,
        youngs,
        poisson,
        restitution=None,
        friction=0.0,
        rolling_friction=0.0,
        rolling: str = "cdt",
        rolling_damping=0.0,
        limit_force: bool = False,
        cohesion_energy=0.0,
        yield_pressure=None,
        characteristic_velocity: float | None = None,
    ) -> None:
        """Choose the contact model and give per-type material arrays (one entry per type).

        ``kind``: ``"hooke"`` (needs ``restitution`` and ``characteristic_velocity``),
        ``"hertz"`` (needs ``restitution``) or ``"thornton-ning"`` (needs
        ``yield_pressure``; ``cohesion_energy`` is the JKR surface energy in J/m^2, for the
        others the SJKR energy density in J/m^3). ``rolling``: the rolling resistance model,
        ``"cdt"``, ``"epsd"`` (damped by ``rolling_damping``, LIGGGHTS'
        coefficientRollingViscousDamping) or ``"epsd2"``. ``limit_force``: keep the hooke and hertz
        visco-elastic normal force from turning attractive (LIGGGHTS ``limitForce on``; cohesion
        still attracts). Particle and wall types index these
        arrays. Changing the model to one with another history layout clears histories.
        """
        tables, self._model = _model_tables(
            kind,
            youngs=youngs,
            poisson=poisson,
            restitution=restitution,
            friction=friction,
            rolling_friction=rolling_friction,
            rolling=rolling,
            rolling_damping=rolling_damping,
            limit_force=limit_force,
            cohesion_energy=cohesion_energy,
            yield_pressure=yield_pressure,
            characteristic_velocity=characteristic_velocity,
        )
        self._core.set_model(*tables)
        nt = self.ntypes
        if self._viscous.shape[0] != nt:
            self._viscous = np.resize(self._viscous, nt) * (np.arange(nt) < self._viscous.shape[0])
        self._core.set_viscous(self._viscous)

    @property
    def ntypes(self) -> int:
        """Number of material types of the contact model (0 before :meth:`set_contact_model`)."""
        return 0 if self._model is None else self._model["youngs"].shape[0]

    def _check_types(self, types: np.ndarray, name: str) -> None:
        if self._model is None:
            raise ConfigError(f"{name}: call set_contact_model before adding particles or walls.")
        if types.size and (types.min() < 0 or types.max() >= self.ntypes):
            raise ConfigError(
                f"{name}: types must lie in [0, {self.ntypes - 1}], got {types.min()}..{types.max()}."
            )

    def set_viscous(self, gamma) -> None:
        """Viscous damping ``F = -gamma v`` with ``gamma`` (kg/s) per type."""
        if self._model is None:
            raise ConfigError("gamma: call set_contact_model first.")
        gamma = _array(
            np.broadcast_to(np.asarray(gamma, float), (self.ntypes,)) if np.ndim(gamma) == 0 else gamma,
            "gamma",
            (self.ntypes,),
        )
        if np.any(gamma < 0):
            raise ConfigError(f"gamma: must be >= 0, got {gamma.tolist()}.")
        self._viscous = gamma.copy()
        self._core.set_viscous(self._viscous)

    # --- particles ---------------------------------------------------------------------
    def add_particles(
        self, positions, radii, densities=None, types=0, velocities=None, omegas=None, masses=None
    ) -> np.ndarray:
        """Add spheres; returns their ids. Give ``densities`` or ``masses`` (scalars broadcast)."""
        x = _array(positions, "positions", (-1, 3))
        n = x.shape[0]
        r = _per_particle(radii, "radii", n)
        if np.any(r <= 0):
            raise ConfigError("radii: must be > 0.")
        if (densities is None) == (masses is None):
            raise ConfigError("densities/masses: give exactly one of them.")
        if masses is None:
            rho = _per_particle(densities, "densities", n)
            if np.any(rho <= 0):
                raise ConfigError("densities: must be > 0.")
            m = 4.0 / 3.0 * np.pi * r**3 * rho
        else:
            m = _per_particle(masses, "masses", n)
            if np.any(m <= 0):
                raise ConfigError("masses: must be > 0.")
        t = _per_particle(types, "types", n, np.int32)
        self._check_types(t, "types")
        v = np.zeros((n, 3)) if velocities is None else _array(velocities, "velocities", (n, 3))
        w = np.zeros((n, 3)) if omegas is None else _array(omegas, "omegas", (n, 3))
        self._check_inside(x, "positions")
        first = self._next_id
        self._core.add_particles(x, r, np.ascontiguousarray(m), t, v, w, first)
        self._next_id += n
        return np.arange(first, first + n, dtype=np.int64)

    def _check_inside(self, x: np.ndarray, name: str) -> None:
        for d in range(3):
            if not self.periodic[d] and np.any((x[:, d] < self.box[0, d]) | (x[:, d] > self.box[1, d])):
                raise ConfigError(f"{name}: outside the fixed boundary of axis {'xyz'[d]}.")

    def add_clumps(
        self, spheres, positions, density: float, orientations=None, types=0, velocities=None, omegas=None
    ) -> np.ndarray:
        """Add rigid clumps of the template ``spheres`` (rows ``x, y, z, r`` in the clump's own
        frame) of ``density``: the template's origin at each of ``positions``, turned by
        ``orientations`` (unit quaternions ``w, x, y, z``; default: as the template), moving at
        ``velocities`` (of the centre of mass) and ``omegas``. Returns the clumps' ids; their
        spheres' ids follow each other, clump by clump (see :attr:`bodies`)."""
        x = _array(positions, "positions", (-1, 3))
        n = x.shape[0]
        if not (math.isfinite(density) and density > 0):
            raise ConfigError(f"density: must be > 0, got {density!r}.")
        try:
            props = clumps.mass_properties(_array(spheres, "spheres", (-1, 4)), density)
        except ValueError as exc:
            raise ConfigError(f"spheres: {exc}.") from None
        template = np.asarray(spheres, float)
        q = (
            np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
            if orientations is None
            else _array(orientations, "orientations", (n, 4))
        )
        if np.any(np.abs(np.linalg.norm(q, axis=1) - 1) > 1e-9):
            raise ConfigError("orientations: quaternions must have length 1.")
        t = _per_particle(types, "types", n, np.int32)
        self._check_types(t, "types")
        v = np.zeros((n, 3)) if velocities is None else _array(velocities, "velocities", (n, 3))
        w = np.zeros((n, 3)) if omegas is None else _array(omegas, "omegas", (n, 3))
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

    def _index(self, ids, name: str) -> np.ndarray:
        """Storage indices of the particles with these ids (ConfigError for unknown ids)."""
        ids = _array(np.atleast_1d(ids), name, (-1,), np.int64)
        stored = self._core.array("id")
        order = np.argsort(stored)
        pos = np.searchsorted(stored[order], ids)
        pos = np.minimum(pos, max(len(stored) - 1, 0))
        if len(stored) == 0 or np.any(stored[order][pos] != ids):
            raise ConfigError(f"{name}: unknown particle id(s) {np.setdiff1d(ids, stored).tolist()}.")
        return np.ascontiguousarray(order[pos], dtype=np.int32)

    def remove_particles(self, ids) -> None:
        """Delete particles by id (with their contacts; a clump's sphere: the whole clump)."""
        index = self._index(ids, "ids")
        mask = np.zeros(self.n, np.uint8)
        mask[index] = 1
        self._core.mark_removed(mask)
        self._core.run(0, 1.0)  # rebuild now so n and the arrays reflect the removal

    def _free(self, ids, name: str) -> np.ndarray:
        """Storage indices of the particles with these ids, none a clump's sphere."""
        index = self._index(ids, name)
        body = self._core.array("body")[index]
        if np.any(body >= 0):
            raise ConfigError(
                f"{name}: particle(s) {self._core.array('id')[index[body >= 0]].tolist()} are spheres of "
                "clumps, which move and grow with their clump only."
            )
        return index

    def set_velocities(self, ids, velocities) -> None:
        """Assign translational velocities to the particles with these ids (not clumps' spheres)."""
        index = self._free(ids, "ids")
        self._core.set_vectors("v", index, _array(velocities, "velocities", (len(index), 3)))

    def set_omegas(self, ids, omegas) -> None:
        """Assign angular velocities to the particles with these ids (not clumps' spheres)."""
        index = self._free(ids, "ids")
        self._core.set_vectors("w", index, _array(omegas, "omegas", (len(index), 3)))

    def set_radii(self, ids, radii) -> None:
        """Assign radii to the particles with these ids (not clumps' spheres); masses follow at
        constant density."""
        index = self._free(ids, "ids")
        r = _per_particle(radii, "radii", len(index))
        if np.any(r <= 0):
            raise ConfigError("radii: must be > 0.")
        old_r, old_m = self._core.array("r")[index], self._core.array("m")[index]
        self._core.set_radii(index, r, np.ascontiguousarray(old_m * (r / old_r) ** 3))

    # --- walls -------------------------------------------------------------------------
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
        p = _array(point, "point", (3,))
        nrm = _array(normal, "normal", (3,))
        length = np.linalg.norm(nrm)
        if length == 0:
            raise ConfigError("normal: must not be zero.")
        geo = np.concatenate([p, nrm / length, np.zeros(3)])[None]
        return self._add_wall("plane", [0], type, geo, np.full((1, 3), -1))

    def add_cylinder(self, axis: str, centre, radius: float, type: int = 0, inside: bool = True) -> int:
        """Infinite cylinder along ``axis`` through ``centre`` (the two other coordinates)."""
        if axis not in ("x", "y", "z"):
            raise ConfigError(f"axis: must be 'x', 'y' or 'z', got {axis!r}.")
        c = _array(centre, "centre", (2,))
        if not (math.isfinite(radius) and radius > 0):
            raise ConfigError(f"radius: must be > 0, got {radius!r}.")
        geo = np.array([[float("xyz".index(axis)), c[0], c[1], radius, 1.0 if inside else 0.0, 0, 0, 0, 0]])
        return self._add_wall("cylinder", [1], type, geo, np.full((1, 3), -1))

    def add_mesh(self, vertices, triangles, type: int = 0) -> int:
        """Triangle-mesh wall; duplicate vertices are merged and zero-area triangles dropped."""
        verts = _array(vertices, "vertices", (-1, 3))
        tris = _array(triangles, "triangles", (-1, 3), np.int64)
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
        if slot is not None and slot[_S.CONTROL] != 0:
            raise ConfigError(f"mesh: {mesh!r} is a servo wall, which its controller moves.")
        amplitude = _array(amplitude, "amplitude", (3,))
        if period is not None and not (math.isfinite(period) and period > 0):
            raise ConfigError(f"period: must be > 0, got {period!r}.")
        if np.any(amplitude != 0) and period is None:
            raise ConfigError("period: a wiggle amplitude needs a period.")
        self._set_vibration(mesh, None)
        self._core.set_motion(
            mesh,
            _array(velocity, "velocity", (3,)),
            _array(angular_velocity, "angular_velocity", (3,)),
            _array(origin, "origin", (3,)),
            amplitude,
            0.0 if period is None or not np.any(amplitude != 0) else float(period),
        )

    def _slot(self, mesh: int) -> np.ndarray | None:
        """The stress values of a mesh (see _S), None if its force is not summed."""
        rows = [row for row in self._core.get_slots() if row[_S.WALL] == mesh]
        return rows[0] if rows else None

    def _put_slot(self, row: np.ndarray) -> None:
        slots = [r for r in self._core.get_slots() if r[_S.WALL] != row[_S.WALL]]
        self._core.set_slots(np.ascontiguousarray(np.reshape([*slots, row], (-1, SLOT_VALUES))))

    def set_stress(self, mesh: int, reference=(0.0, 0.0, 0.0)) -> None:
        """Sum the force of the particles on a mesh, and their torque about ``reference``, at
        every step (LIGGGHTS ``mesh/surface/stress``): :meth:`mesh_force`."""
        if self._walls.get(mesh) != "mesh":
            raise ConfigError(f"mesh: {mesh!r} is not a mesh of this solver.")
        if self._slot(mesh) is not None:
            raise ConfigError(f"mesh: the force on mesh {mesh!r} is summed already.")
        row = np.zeros(SLOT_VALUES)
        row[_S.WALL] = mesh
        row[_S.COM] = row[_S.COM0] = _array(reference, "reference", (3,))
        row[_S.ARM] = 1.0
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
        direction = _array(axis, "axis", (3,))
        length = float(np.linalg.norm(direction))
        if length == 0:
            raise ConfigError("axis: must not be zero.")
        direction = direction / length
        centre = _array(com, "com", (3,))
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
        row[_S.WALL] = mesh
        row[_S.CONTROL] = _CONTROLS.index(control)
        row[_S.AUTO] = mode == "auto"
        row[_S.SET_POINT] = -target  # LIGGGHTS: the particles' force acts against the push
        row[_S.VEL_MAX] = vel_max
        row[_S.KP], row[_S.KI], row[_S.KD] = kp, ki, kd
        row[_S.RATIO] = ratio or 0.0
        row[_S.ARM] = arm
        row[_S.OUTPUT_MAX] = vel_max / arm
        row[_S.AXIS] = direction
        row[_S.COM] = row[_S.COM0] = centre
        self._put_slot(row)

    def mesh_force(self, mesh: int) -> tuple[np.ndarray, np.ndarray]:
        """The particles' force (N) on a stress or servo mesh at the last step, and their
        torque (N m) about its reference point (a servo's com)."""
        row = self._slot(mesh)
        if row is None:
            raise ConfigError(f"mesh: {mesh!r} is not a stress or servo mesh of this solver (set_stress).")
        return row[_S.FORCE].copy(), row[_S.TORQUE].copy()

    def servo_state(self, mesh: int) -> dict[str, float | np.ndarray]:
        """A servo's controller: its ``com`` (m), turned ``angle`` (rad), output ``velocity``
        (m/s or rad/s, a vector), error ``integral`` and ``previous`` process value."""
        row = self._slot(mesh)
        if row is None or row[_S.CONTROL] == 0:
            raise ConfigError(f"mesh: {mesh!r} is not a servo mesh of this solver (set_servo).")
        return {
            "com": row[_S.COM].copy(),
            "angle": float(row[_S.ANGLE]),
            "velocity": row[_S.VELOCITY].copy(),
            "integral": float(row[_S.INTEGRAL]),
            "previous": float(row[_S.PREVIOUS]),
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
        if kind not in _VIBRATIONS:
            raise ConfigError(f"kind: 'viblin' or 'vibrot', got {kind!r}.")
        slot = self._slot(mesh)
        if slot is not None and slot[_S.CONTROL] != 0:
            raise ConfigError(f"mesh: {mesh!r} is a servo wall, which its controller moves.")
        direction = _array(axis, "axis", (3,))
        if not np.any(direction != 0):
            raise ConfigError("axis: must not be zero.")
        amp = _array(np.atleast_1d(amplitudes), "amplitudes", (-1,))
        order = amp.shape[0]
        if not 1 <= order <= HARMONICS:
            raise ConfigError(f"amplitudes: 1 to {HARMONICS} harmonics, got {order}.")
        phase = _array(np.atleast_1d(phases), "phases", (order,))
        period = _array(np.atleast_1d(periods), "periods", (order,))
        if np.any(period <= 0):
            raise ConfigError(f"periods: must be > 0, got {period.tolist()}.")
        row = np.zeros(VIBRATION_VALUES)
        row[_V.WALL], row[_V.KIND], row[_V.ORDER] = mesh, 1 + _VIBRATIONS.index(kind), order
        row[_V.AXIS] = direction / np.linalg.norm(direction)
        row[_V.AMPLITUDE][:order] = amp
        row[_V.PHASE][:order] = phase
        row[_V.FREQUENCY][:order] = 2 * np.pi / period
        zero = np.zeros(3)
        self._set_vibration(mesh, None)
        self._core.set_motion(mesh, zero, zero, _array(origin, "origin", (3,)), zero, 0.0)
        self._set_vibration(mesh, row)

    def _set_vibration(self, mesh: int, row: np.ndarray | None) -> None:
        """Replace the vibration of a mesh by ``row`` (None: no vibration)."""
        rows = [r for r in self._core.get_vibrations() if r[_V.WALL] != mesh] + ([] if row is None else [row])
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

    # --- running -----------------------------------------------------------------------
    def run(self, nsteps: int, dt: float) -> None:
        """Advance ``nsteps`` steps of ``dt`` seconds (compiled, no Python in the loop)."""
        if not (isinstance(nsteps, (int, np.integer)) and nsteps >= 0):
            raise ConfigError(f"nsteps: must be a non-negative integer, got {nsteps!r}.")
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"dt: must be > 0, got {dt!r}.")
        if self._model is None:
            raise ConfigError("set_contact_model must be called before run.")
        for row in self._core.get_slots():
            if row[_S.CONTROL] and not row[_S.VEL_MAX] < self._core.skin / (2 * dt):
                raise ConfigError(
                    f"vel_max: a servo's {row[_S.VEL_MAX]:g} m/s must be below skin / (2 dt) = "
                    f"{self._core.skin / (2 * dt):g} m/s (as LIGGGHTS: it moves at most half the skin "
                    "per step); lower it or dt, or raise the skin."
                )
        if self.n:
            reach = 2 * self._core.largest_radius() + self._core.skin
            for d in range(3):
                if self.periodic[d] and self.box[1, d] - self.box[0, d] < 2 * reach:
                    raise ConfigError(
                        f"box: the periodic axis {'xyz'[d]} must be at least 2 (2 r_max + skin) "
                        f"= {2 * reach:g} long."
                    )
        self._core.run(int(nsteps), float(dt))

    # --- outputs -----------------------------------------------------------------------
    def _sorted(self, name: str) -> np.ndarray:
        return self._core.by_id(name)

    n = property(lambda self: self._core.n, doc="Number of particles.")
    time = property(lambda self: self._core.time, doc="Simulated time (s).")
    step = property(lambda self: self._core.step, doc="Steps run so far.")
    lost = property(
        lambda self: self._core.lost,
        doc="Particles deleted for leaving a fixed boundary or becoming non-finite.",
    )

    def take_lost(self) -> tuple[dict[str, int], float | None]:
        """Particles lost since the last call (part of :meth:`get_state`): counts by place, a
        face of the box (``"z-"``: below its lower z bound; the one a particle is furthest
        beyond) or ``"non-finite"``, and the largest speed (m/s) of those lost through a face,
        ``None`` if there were none."""
        counts, speed = self._core.take_lost()
        where = {place: int(k) for place, k in zip(LOST_PLACES, counts) if k}
        return where, (speed if sum(where.values()) > where.get("non-finite", 0) else None)

    positions = property(lambda self: self._sorted("x"), doc="(n, 3) positions, by id.")
    velocities = property(lambda self: self._sorted("v"), doc="(n, 3) velocities, by id.")
    omegas = property(lambda self: self._sorted("w"), doc="(n, 3) angular velocities, by id.")
    forces = property(lambda self: self._sorted("f"), doc="(n, 3) forces at the last step, by id.")
    torques = property(lambda self: self._sorted("t"), doc="(n, 3) torques at the last step, by id.")
    radii = property(lambda self: self._sorted("r"), doc="(n,) radii, by id.")
    masses = property(lambda self: self._sorted("m"), doc="(n,) masses, by id.")
    types = property(lambda self: self._sorted("type"), doc="(n,) types, by id.")
    ids = property(lambda self: self._sorted("id"), doc="(n,) ids, ascending.")
    bodies = property(
        lambda self: self._sorted("body"), doc="(n,) the clump of each particle (-1: a free sphere), by id."
    )

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

    def contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Particle-particle contacts at the last step: ``(i_ids, j_ids, overlap, normal_force)``."""
        i, j, overlap, force = self._core.contacts()
        ids = self._core.array("id")
        return ids[i], ids[j], overlap, force

    def contact_forces(self) -> dict[str, np.ndarray]:
        """Contacts at the last step, with the forces the step applied, pairs then walls: ids
        ``id1``, ``id2`` (int64; a wall contact has ``id2 = -(handle + 1)`` with the wall's
        handle), the total contact force on id1 by id2 ``fx, fy, fz`` (normal and tangential; id2
        gets the opposite), the contact point ``cx, cy, cz`` and the branch vector ``bx, by, bz``
        = x1 - x2 (across a periodic boundary, to the image in contact). A pair's point is the
        middle of the overlap on the line of centres; a wall's is on its surface (the closest
        point of the mesh triangle the contact used, the foot point on a plane or cylinder),
        with ``b = x1 - c``; a particle on a flat mesh surface has one contact however many of
        its triangles it reaches. A ConfigError after :meth:`set_state` until a run evaluates
        the forces (they are not part of a checkpoint), and when :attr:`record_contacts` is off."""
        if not self.record_contacts:
            raise ConfigError(
                "contact_forces: the solver does not keep contact forces; set record_contacts = True "
                "and run a step first."
            )
        try:
            return self._core.contact_forces()
        except ValueError:
            raise ConfigError(
                "contact_forces: no step since the state was restored or record_contacts was set; "
                "run a step first."
            ) from None

    @property
    def record_contacts(self) -> bool:
        """Whether a run keeps each contact's force for :meth:`contact_forces` (3 values per
        contact, 24 bytes; on unless set off)."""
        return self._core.recording

    @record_contacts.setter
    def record_contacts(self, on: bool) -> None:
        self._core.set_recording(bool(on))

    def kinetic_energy(self, types=None) -> tuple[float, float]:
        """Translational and rotational kinetic energy (J) of the free spheres and the clumps (of
        ``types`` only, if given)."""
        m, r = self._core.array("m"), self._core.array("r")
        v, w = self._core.array("v"), self._core.array("w")
        if self._core.nbody == 0 and types is None:
            return float(0.5 * np.sum(m * np.sum(v * v, axis=1))), float(
                0.2 * np.sum(m * r * r * np.sum(w * w, axis=1))
            )
        free = self._core.array("body") < 0
        found = self._core.bodies()
        if types is not None:
            free &= np.isin(self._core.array("type"), types)
            found = {key: value[np.isin(found["type"], types)] for key, value in found.items()}
        translation = 0.5 * np.sum(m[free] * np.sum(v[free] ** 2, axis=1))
        rotation = 0.2 * np.sum(m[free] * r[free] ** 2 * np.sum(w[free] ** 2, axis=1))
        translation += 0.5 * np.sum(found["m"] * np.sum(found["v"] ** 2, axis=1))
        rotation += 0.5 * np.sum(found["p"] ** 2 / found["inertia"])
        return float(translation), float(rotation)

    @property
    def memory(self) -> dict[str, int]:
        """Bytes the solver has allocated (capacity), by part: see ``Core.memory``."""
        return {part: int(size) for part, size in self._core.memory().items()}

    @property
    def memory_bytes(self) -> int:
        """Bytes the solver has allocated in all (:attr:`memory`)."""
        return sum(self.memory.values())

    @property
    def list_entries(self) -> tuple[int, int]:
        """Entries of the neighbour list (pairs within reach) and of the wall list."""
        pairs, walls = self._core.list_entries()
        return int(pairs), int(walls)

    @property
    def timings(self) -> dict:
        """Seconds spent in :meth:`run` so far, by phase (wall clock): ``run`` (all of it),
        ``drift`` (first half kicks not fused with the previous step, and passes measuring
        displacements), ``walls`` (moving the
        meshes), ``pairs`` (pair and wall forces), ``particles`` (summing them, gravity,
        viscous forces, integration, clumps' bodies, servo walls; with threads the two loops
        overlap, and ``pairs`` ends when the calling thread starts on the particles),
        ``rebuild`` and its parts ``rebuild_cells``, ``rebuild_sort``, ``rebuild_permute``,
        ``rebuild_count``, ``rebuild_fill``; the CPU seconds of each thread in the pair and
        particle loops (arrays ``pairs_cpu``, ``particles_cpu``, without waits), and the sum
        over steps of the busiest thread's CPU seconds in both (``forces_span``: a lower bound
        of their wall time on otherwise idle cores), and the steps the
        calling thread ran without the others, having found that faster (``solo_steps``: on
        a busy machine or a small system), how often a thread woken next to a teammate
        moved to a CPU of the team's that none was on (``moves``: on a busy machine), and how
        often the pair loop built its sublist of the pairs near contact (``sublist_builds``:
        hertz without rolling resistance skips the other listed pairs until a particle may
        have moved far enough to reach one), and of the steps, how many drifts measured each
        particle's displacement for the rebuild check (``measured_drifts``) and how many passes
        measured them after a drift that did not (``displacement_passes``; the other steps'
        speeds ruled a rebuild out). Not part of :meth:`get_state`."""
        return self._core.timings()

    @property
    def rebuilds(self) -> int:
        """Neighbour-list rebuilds so far."""
        return int(self._core.rebuilds)

    # --- checkpoints -------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        """Everything needed to continue bitwise identically, as a dict of numpy arrays.

        Numeric arrays only (strings are UTF-8 bytes), so it can be stored in HDF5 as is.
        """
        if self._model is None:
            raise ConfigError("get_state: no contact model set yet.")
        state = {f"core_{k}": v for k, v in self._core.get_state().items()}
        model = self._model
        state["model_kind"] = encode_text(model["kind"])
        state["model_rolling"] = encode_text(model["rolling"])
        for key in _MODEL_KEYS:
            state[f"model_{key}"] = np.array(np.nan if model[key] is None else model[key], float)
        state["viscous"] = self._viscous.copy()
        state["counters"] = np.array([self._next_id, self._next_wall, self._next_vertex], np.int64)
        if self._next_body:
            state["clump_counter"] = np.array([self._next_body], np.int64)
        state["wall_handles"] = np.array(list(self._walls), np.int64)
        state["wall_kinds"] = np.array([_WALL_KINDS.index(k) for k in self._walls.values()], np.int64)
        state["rng"] = encode_text(json.dumps(self.rng.bit_generator.state))
        return state

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore a :meth:`get_state` result (box, periodicity and threads are this solver's).

        Every entry is checked, against the particle count, the others and the solver's layout,
        before anything is changed: a malformed state is a :class:`ReadError` naming the entry
        and what it should hold, and leaves the solver as it was.
        """
        try:
            checked = _checked_state(state, self.periodic)
        except ReadError:
            raise
        except (KeyError, IndexError, ValueError, TypeError, AttributeError, OverflowError) as exc:
            # a JSON or UTF-8 decoding error is a ValueError
            raise ReadError(f"checkpoint state: malformed ({type(exc).__name__}: {exc})") from None
        tables, model, viscous, core, counters, walls, rng = checked
        self._core.set_model(*tables)
        self._model = model
        self._viscous = viscous
        self._core.set_viscous(viscous)
        self._core.set_state(core)
        self._next_id, self._next_wall, self._next_vertex, self._next_body = counters
        self._walls = walls
        self.rng.bit_generator.state = rng


# --- checking a state ------------------------------------------------------------------
_IMAGES = 27  #: periodic image codes 9 (sx + 1) + 3 (sy + 1) + (sz + 1) of the neighbour list
_FLAGS = 0x80 | 0x40  #: the other bits of a neighbour-list code (TOUCH, WRAP; see _solver.pyx)


def _fail(key: str, expected: str, found: object = None) -> ReadError:
    got = "" if found is None else f", found {found}"
    return ReadError(f"checkpoint state entry {key!r}: expected {expected}{got}.")


def _entry(
    state: Mapping[str, np.ndarray], key: str, dtype, length: int | None = None, basis: str = ""
) -> np.ndarray:
    """``state[key]`` as a flat array of exactly ``dtype`` (and ``length``, which ``basis``
    explains), or a ReadError."""
    if key not in state:
        raise ReadError(f"checkpoint state: missing entry {key!r}.")
    value = np.asarray(state[key])
    dtype = np.dtype(dtype)
    if value.dtype != dtype:
        raise _fail(key, f"{dtype} values", value.dtype)
    if value.ndim != 1:
        raise _fail(key, "a one-dimensional array", f"shape {value.shape}")
    if length is not None and value.shape[0] != length:
        raise _fail(key, f"{length} values{basis}", value.shape[0])
    return np.ascontiguousarray(value)


def _text(state: Mapping[str, np.ndarray], key: str) -> str:
    """``state[key]``, UTF-8 text stored as bytes, or a ReadError."""
    try:
        return decode_text(_entry(state, key, np.uint8))
    except UnicodeDecodeError as exc:
        raise _fail(key, "UTF-8 text", f"bytes that are not: {exc}") from None


def _within(key: str, values: np.ndarray, lo: float, hi: float, what: str = "") -> None:
    """Every value finite and in [lo, hi), or a ReadError."""
    ok = np.isfinite(values) & (values >= lo) & (values < hi) if values.size else np.ones(0, bool)
    if not np.all(ok):
        bad = values[~ok][0]
        raise _fail(key, what or f"values in [{lo:g}, {hi:g})", f"{bad!r}")


def _offsets(key: str, start: np.ndarray, total: int, listed: str) -> None:
    """CSR offsets: from 0, non-decreasing, ending at ``total`` (the length of ``listed``)."""
    if start[0] != 0 or np.any(np.diff(start) < 0) or start[-1] != total:
        raise _fail(
            key,
            f"offsets from 0, non-decreasing, up to the length {total} of {listed}",
            f"{start[0]}..{start[-1]}" + (" (decreasing somewhere)" if np.any(np.diff(start) < 0) else ""),
        )


def _checked_state(state: Mapping[str, np.ndarray], periodic: tuple[bool, ...]):
    """What :meth:`Solver.set_state` applies, each entry checked (see there)."""
    kind = _text(state, "model_kind")
    if kind not in _MODELS:
        raise _fail("model_kind", f"one of {', '.join(_MODELS)}", repr(kind))
    settings = {}
    for key in _MODEL_KEYS:
        value = np.asarray(state[f"model_{key}"]) if f"model_{key}" in state else None
        if value is None or value.dtype != np.float64 or value.ndim > 2:
            raise _fail(
                f"model_{key}",
                "a float64 number, one per type or a pair matrix",
                None if value is None else value.dtype,
            )
        settings[key] = (
            None if value.ndim == 0 and np.isnan(value) else (float(value) if value.ndim == 0 else value)
        )
    rolling = _text(state, "model_rolling")
    if rolling not in _ROLLING:
        raise _fail("model_rolling", f"one of {', '.join(_ROLLING)}", repr(rolling))
    try:
        tables, model = _model_tables(kind, rolling=rolling, **settings)
    except ConfigError as exc:  # "poisson: expected ..."
        name, _, problem = str(exc).partition(": ")
        youngs = settings["youngs"]
        types = 0 if youngs is None else np.size(youngs)
        raise ReadError(
            f"checkpoint state entry 'model_{name}': {problem} (model_youngs gives {types} types)"
        ) from None
    nt, hs = model["youngs"].shape[0], tables[1]
    viscous = _entry(state, "viscous", float, nt, " (one per type of model_youngs)")
    _within("viscous", viscous, 0, np.inf, "damping coefficients >= 0")

    def get(key, dtype, length=None, basis=""):
        return _entry(state, f"core_{key}", dtype, length, basis and f" ({basis})")

    out = {}
    r = out["r"] = get("r", float)
    n = r.shape[0]
    for key in ("x", "v", "w", "f", "t", "x0"):
        out[key] = get(key, float, 3 * n, "3 per particle of core_r")
    out["m"] = get("m", float, n, "one per particle of core_r")
    _within("core_r", r, 0, np.inf, "radii > 0")
    _within("core_m", out["m"], 0, np.inf, "masses > 0")
    for key in ("r", "m"):
        if np.any(out[key] == 0):
            raise _fail(f"core_{key}", "values > 0", 0.0)
    out["type"] = get("type", np.int32, n, "one per particle of core_r")
    _within("core_type", out["type"], 0, nt, f"types in [0, {nt - 1}]")
    ids = out["id"] = get("id", np.int64, n, "one per particle of core_r")
    _within("core_id", ids, 0, np.inf, "ids >= 0")
    if len(np.unique(ids)) != n:
        raise _fail("core_id", "distinct ids", "repeated ids")
    # neighbour list: rows in storage order, partners j > i (a half list), image codes
    nb_start = out["nb_start"] = get("nb_start", np.int32, n + 1, "one more than the particles of core_r")
    nb_j = out["nb_j"] = get("nb_j", np.int32)
    npair = nb_j.shape[0]
    _offsets("core_nb_start", nb_start, npair, "core_nb_j")
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(nb_start))
    if np.any(nb_j >= n) or np.any(nb_j <= rows):
        raise _fail("core_nb_j", f"partners j of row i with i < j < {n}", "others")
    nb_s = out["nb_s"] = get("nb_s", np.uint8, npair, "one per pair of core_nb_j")
    image = nb_s & ~np.uint8(_FLAGS)
    shifts = np.stack([image // 9, image // 3 % 3, image % 3], axis=1) if npair else np.ones((0, 3), int)
    if np.any(image >= _IMAGES) or np.any((shifts != 1) & ~np.array(periodic)):
        raise _fail("core_nb_s", "periodic image codes 0..26 across periodic axes only", "others")
    out["nb_h"] = get("nb_h", float, npair * hs, f"{hs} per pair of core_nb_j")
    # wall elements and the wall list
    ekind = out["ekind"] = get("ekind", np.int32)
    ne = ekind.shape[0]
    _within("core_ekind", ekind, 0, 3, "element kinds 0 (plane), 1 (cylinder), 2 (triangle)")
    out["etype"] = get("etype", np.int32, ne, "one per element of core_ekind")
    _within("core_etype", out["etype"], 0, nt, f"types in [0, {nt - 1}]")
    out["ewall"] = get("ewall", np.int32, ne, "one per element of core_ekind")
    out["evid"] = get("evid", np.int32, 3 * ne, "3 per element of core_ekind")
    _within("core_evid", out["evid"], -1, np.inf, "vertex ids >= -1")
    out["emoving"] = get("emoving", np.int32, ne, "one per element of core_ekind")
    _within("core_emoving", out["emoving"], 0, 2, "flags 0 or 1")
    for key in ("egeo", "eref", "ebuilt"):
        out[key] = get(key, float, 9 * ne, "9 per element of core_ekind")
        _within(f"core_{key}", out[key], -np.inf, np.inf, "finite coordinates")
    out["emot"] = get("emot", float, MOTION_VALUES * ne, f"{MOTION_VALUES} per element of core_ekind")
    _within("core_emot", out["emot"], -np.inf, np.inf, "finite motion values")
    geo = out["egeo"].reshape(ne, 9)
    cylinders = geo[ekind == 1]
    if np.any(~np.isin(cylinders[:, 0], (0.0, 1.0, 2.0))) or np.any(cylinders[:, 3] <= 0):
        raise _fail("core_egeo", "cylinders with an axis 0, 1 or 2 and a radius > 0", "others")
    wl_start = out["wl_start"] = get("wl_start", np.int32, n + 1, "one more than the particles of core_r")
    wl_e = out["wl_e"] = get("wl_e", np.int32)
    nwall = wl_e.shape[0]
    _offsets("core_wl_start", wl_start, nwall, "core_wl_e")
    _within("core_wl_e", wl_e, 0, ne, f"wall elements in [0, {ne - 1}]")
    wl_h = out["wl_h"] = get("wl_h", float, nwall * (hs + 1), f"{hs + 1} per entry of core_wl_e")
    if nwall and not np.all(np.isin(wl_h.reshape(nwall, hs + 1)[:, hs], (-1.0, 0.0, 1.0))):
        raise _fail("core_wl_h", "plane sides -1, 0 or 1 after each entry's history")
    out["visc"] = get("visc", float, nt, "one per type of model_youngs")
    _within("core_visc", out["visc"], 0, np.inf, "damping coefficients >= 0")
    out["scalars"] = get("scalars", float, 4)
    _within("core_scalars", out["scalars"], -np.inf, np.inf, "finite time, time base, step, lost speed")
    if out["scalars"][3] < 0:
        raise _fail("core_scalars", "a lost particles' speed >= 0", out["scalars"][3])
    out["lost"] = get("lost", np.int64, len(LOST_PLACES), "one per place of LOST_PLACES")
    _within("core_lost", out["lost"], 0, np.inf, "counts >= 0")
    out["counters"] = counters = get("counters", np.int64, 5)
    step, lost, rebuilds, dirty, step_base = counters.tolist()
    if min(step, lost, rebuilds, step_base) < 0 or dirty not in (0, 1) or step_base > step:
        raise _fail("core_counters", "step, lost, rebuilds >= 0, dirty 0 or 1, 0 <= step base <= step")
    bounds = out["bounds"] = get("bounds", np.int32)
    # the bounds of the last pair loop: they end at n unless particles were added since (dirty:
    # the lists and bounds are made anew before the next pair loop)
    if (
        bounds.shape[0] < 2
        or bounds[0] != 0
        or np.any(np.diff(bounds) < 0)
        or not (bounds[-1] == n or (dirty and bounds[-1] <= n))
    ):
        raise _fail(
            "core_bounds",
            f"block bounds from 0, non-decreasing, up to the particle count {n} (at most, if dirty)",
        )
    # the solver's own entries
    next_id, next_wall, next_vertex = _entry(state, "counters", np.int64, 3).tolist()
    next_body = 0  # clumps made so far: absent without any
    if "clump_counter" in state:
        (next_body,) = _entry(state, "clump_counter", np.int64, 1).tolist()
    handles = _entry(state, "wall_handles", np.int64)
    kinds = _entry(state, "wall_kinds", np.int64, handles.shape[0], " (one per wall of wall_handles)")
    _within("wall_handles", handles, 0, next_wall, f"handles in [0, {next_wall})")
    _within("wall_kinds", kinds, 0, len(_WALL_KINDS), "0 (plane), 1 (cylinder) or 2 (mesh)")
    walls = {int(h): _WALL_KINDS[int(k)] for h, k in zip(handles, kinds)}
    if len(walls) != handles.shape[0]:
        raise _fail("wall_handles", "distinct handles", "repeated ones")
    owner = [walls.get(int(w)) for w in out["ewall"]]
    if any(o is None or _WALL_KINDS.index(o) != k for o, k in zip(owner, ekind.tolist())):
        raise _fail("core_ewall", "the handle of a wall of the element's kind", "others")
    # stress and servo meshes (absent from checkpoints written before there were any)
    if "core_slots" not in state:
        state = {**state, "core_slots": np.zeros(0)}
    slots = out["slots"] = get("slots", float)
    if slots.shape[0] % SLOT_VALUES:
        raise _fail("core_slots", f"{SLOT_VALUES} values per stress mesh", slots.shape[0])
    _within("core_slots", slots, -np.inf, np.inf, "finite values")
    rows = slots.reshape(-1, SLOT_VALUES)
    meshes = [walls.get(int(w)) == "mesh" and w == int(w) for w in rows[:, _S.WALL]]
    if not all(meshes) or len(set(rows[:, _S.WALL])) != len(rows):
        raise _fail("core_slots", "one row per stress mesh, each naming a mesh wall", "others")
    if not np.all(np.isin(rows[:, _S.CONTROL], (0.0, 1.0, 2.0))):
        raise _fail("core_slots", "controls 0 (stress), 1 (force) or 2 (torque)", "others")
    if np.any(rows[:, _S.ARM] <= 0) or np.any((rows[:, _S.CONTROL] > 0) & (rows[:, _S.SET_POINT] == 0)):
        raise _fail("core_slots", "lever arms > 0 and servo set points != 0", "others")
    if "core_vib" not in state:  # nor vibrating ones
        state = {**state, "core_vib": np.zeros(0)}
    vib = out["vib"] = get("vib", float)
    if vib.shape[0] % VIBRATION_VALUES:
        raise _fail("core_vib", f"{VIBRATION_VALUES} values per vibrating mesh", vib.shape[0])
    _within("core_vib", vib, -np.inf, np.inf, "finite values")
    rows = vib.reshape(-1, VIBRATION_VALUES)
    if (
        not all(walls.get(int(w)) == "mesh" and w == int(w) for w in rows[:, _V.WALL])
        or len(set(rows[:, _V.WALL])) != len(rows)
        or not np.all(np.isin(rows[:, _V.KIND], (1.0, 2.0)))
        or not np.all(np.isin(rows[:, _V.ORDER], np.arange(1, HARMONICS + 1)))
    ):
        raise _fail(
            "core_vib",
            f"one row per vibrating mesh: its wall, kind 1 or 2, 1 to {HARMONICS} harmonics",
            "others",
        )
    if n and next_id <= ids.max() or ne and next_vertex <= out["evid"].max():
        raise _fail("counters", "next particle id and vertex beyond those in use", [next_id, next_vertex])
    _checked_clumps(state, out, nt, next_body)
    try:
        rng = json.loads(_text(state, "rng"))
        type(np.random.default_rng().bit_generator)().state = rng
    except (ValueError, TypeError, KeyError) as exc:
        raise _fail("rng", "the JSON state of a PCG64 generator", f"{type(exc).__name__}: {exc}") from None
    return tables, model, viscous, out, (next_id, next_wall, next_vertex, next_body), walls, rng


#: A checkpoint's per-clump entries (``core_body_<key>``) and their values per clump; the clump
#: entries are there only when there are clumps.
_BODY_VALUES = {"x": 3, "v": 3, "q": 4, "p": 3, "m": 1, "inertia": 3, "f": 3, "t": 3}


def _checked_clumps(state: Mapping[str, np.ndarray], out: dict, nt: int, next_body: int) -> None:
    """The clump entries of a state into ``out``, each checked (see :meth:`Solver.set_state`)."""
    n = out["r"].shape[0]
    if "core_mem" not in state:  # no clumps (the state of spheres only has no clump entries)
        return

    def get(key, dtype, length=None, basis=""):
        return _entry(state, f"core_{key}", dtype, length, basis and f" ({basis})")

    ids = out["body_id"] = get("body_id", np.int64)
    nb = ids.shape[0]
    _within("core_body_id", ids, 0, next_body, f"clump ids in [0, {next_body}) (counters)")
    if len(np.unique(ids)) != nb:
        raise _fail("core_body_id", "distinct clump ids", "repeated ids")
    for key, k in _BODY_VALUES.items():
        out[f"body_{key}"] = get(f"body_{key}", float, k * nb, f"{k} per clump of core_body_id")
        _within(f"core_body_{key}", out[f"body_{key}"], -np.inf, np.inf, "finite values")
    if np.any(out["body_m"] <= 0) or np.any(out["body_inertia"] <= 0):
        raise _fail("core_body_m", "clumps' masses and principal moments > 0")
    if np.any(np.abs(np.linalg.norm(out["body_q"].reshape(nb, 4), axis=1) - 1) > 1e-9):
        raise _fail("core_body_q", "unit quaternions")
    out["body_type"] = get("body_type", np.int32, nb, "one per clump of core_body_id")
    _within("core_body_type", out["body_type"], 0, nt, f"types in [0, {nt - 1}]")
    start = out["body_start"] = get("body_start", np.int32, nb + 1, "one more than the clumps")
    nm = int(start[-1]) if len(start) else 0
    _offsets("core_body_start", start, nm, "the member slots")
    if nb and np.any(np.diff(start) == 0):
        raise _fail("core_body_start", "at least one sphere per clump")
    for key in ("member_offset", "member_shift"):
        out[key] = get(key, float, 3 * nm, "3 per member slot of core_body_start")
        _within(f"core_{key}", out[key], -np.inf, np.inf, "finite values")
    mem = out["mem"] = get("mem", np.int32, n, "one per particle of core_r")
    if not np.array_equal(np.sort(mem[mem >= 0]), np.arange(nm)) or np.any(mem < -1):
        raise _fail("core_mem", f"-1 or a member slot, each of the {nm} slots held by one particle")
