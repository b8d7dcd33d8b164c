"""What the engine base checks and concludes about a simulation, as functions of its spec and
of arrays: the refusals before a solver starts, the bounds on a run's size, the servo limits,
overlaps of created particles, the time step against the contacts that can happen
(:mod:`~pygran_core.simulation.timestep`), where lost particles went and why, and whether a
servo wall's force swings about its target. The :class:`~pygran_core.simulation.engine.Engine`
calls them at the boundary, once; none of them talks to a solver.
"""

from __future__ import annotations

import itertools
import math
import shutil
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from pygran_core.errors import ConfigError, UnsupportedFeature, did_you_mean, unknown_key
from pygran_core.simulation.calls import CreateSpec, MonitorSpec, WallSpec, available_memory
from pygran_core.simulation.output import TRAJ_COLUMNS
from pygran_core.simulation.specs import ServoSpec, SimulationSpec, TrajectorySpec
from pygran_core.simulation.timestep import Assessment, Body, Limits, characteristic_speed, limits

#: The faces of the domain, as lost particles and ``Engine.expect_outflow`` name them.
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")
#: Lost particles faster than this many times what the simulation explains (the
#: characteristic velocity, the speeds given, a fall across the box) point to an instability.
FAST_FACTOR = 10.0
#: A run's last steps are this many single steps when a force servo wall is present, so that
#: the force on it is read at each (:func:`servo_swing`).
SERVO_WATCH = 3
#: A servo's force swinging about its target by more than this fraction of it at each of those
#: steps, one side then the other, is a :class:`~pygran_core.errors.ServoWarning`.
SERVO_SWING = 0.05
#: How deep (a fraction of the smaller radius) particles created at given positions may overlap:
#: a settled bed read from a file has its contacts' overlaps (0.2 % in Dosta et al.'s drum).
CREATE_OVERLAP_TOLERANCE = 1e-2
#: The last step a simulation may reach: step counters are 64-bit integers.
MAX_STEP = 2**63 - 1
#: The fewest bytes a trajectory frame takes on disk (its header, with no particle).
FRAME_BYTES = 100
#: The memory a monitor value takes while kept (a Python float in a tuple), in bytes.
SAMPLE_BYTES = 32

#: (species, smallest radius, more than one) of the particles present.
Present = tuple[tuple[int, float, bool], ...]


@dataclass(frozen=True)
class LostParticles:
    """Particles lost during a run: ``count`` in all, and ``where`` by place: a face of the
    domain they left through (``"z-"``: below the lower z bound, see :data:`FACES`),
    ``"non-finite"`` (position or velocity NaN or infinite) or ``"unknown"``. ``max_speed``
    is the largest speed (m/s) they had when last seen, ``None`` if unknown."""

    count: int = 0
    where: Mapping[str, int] = field(default_factory=dict)
    max_speed: float | None = None

    def __add__(self, other: LostParticles) -> LostParticles:
        where = dict(self.where)
        for place, n in other.where.items():
            where[place] = where.get(place, 0) + n
        speeds = [s for s in (self.max_speed, other.max_speed) if s is not None]
        return LostParticles(self.count + other.count, where, max(speeds, default=None))

    def places(self, exclude: frozenset[str] = frozenset()) -> str:
        """``"150 through z-, 3 non-finite"``, leaving out the places in ``exclude``."""
        named = {"non-finite": "{} became non-finite", "unknown": "{} where the engine cannot tell"}
        parts = [
            named.get(place, "{} through " + place).format(n)
            for place, n in sorted(self.where.items())
            if n and place not in exclude
        ]
        return ", ".join(parts)


# -- before the solver starts, and before each run --------------------------------------------


def check_spec(spec: SimulationSpec, require: Callable[[str, str], None]) -> None:
    """Refuse, before the solver starts, whatever of ``spec`` the engine cannot do:
    ``require(capability, what)`` raises for a capability the engine lacks."""
    model = spec.model
    if model.kernel is None:
        lost_by = model.kernel_lost_by
        raise UnsupportedFeature(
            f"The contact model {model.__name__} declares no kernel (class attribute kernel)"
            + (f": {lost_by} overrides its parent's force law" if lost_by else "")
            + ", so no engine can run it: subclass SpringDashpot, HertzMindlin or ThorntonNing "
            "without overriding __init__ or their force law (normal_force...), or set kernel to the "
            "capability of an engine that runs its law."
        )
    require(model.kernel, f"the {model.__name__} contact model")
    wanted = [
        (model.limit_force, "limit-force", "limitForce=True"),
        (any(spec.domain.periodic), "periodic", "periodic boundaries"),
        (bool(spec.meshes), "mesh-walls", "mesh walls"),
        (spec.restart is not None, "restart", "restart files"),
        (spec.nsim > 1 or spec.nprocs not in (None, 1), "mpi", "several MPI ranks (nSim, nprocs)"),
        (spec.threads not in (None, 1), "threads", "threads"),
        (bool(spec.pairs), "pair-tables", "per-pair material values (pairs=)"),
        (spec.nns_type != "bin", "neighbor-styles", f"the neighbour-list style nns_type={spec.nns_type!r}"),
        (bool(spec.traj.dump_modify), "liggghts-dump", f"dump_modify {spec.traj.dump_modify}"),
        (
            spec.traj.cfile is not None,
            "contact-output",
            f"contact output (traj cfile {getattr(spec.traj.cfile, 'name', '')!r})",
        ),
        (
            spec.traj.margs != TrajectorySpec.margs,
            "liggghts-dump",
            f"traj margs {spec.traj.margs} (the columns of LIGGGHTS' mesh dump)",
        ),
    ]
    for needed, capability, what in wanted:
        if needed:
            require(capability, what)
    unknown = list(dict.fromkeys(c for c in spec.traj.args if c not in TRAJ_COLUMNS))
    if unknown:
        hint = (
            " A string was split into letters: give a sequence of names such as ('id', 'x', 'y', 'z')."
            if all(len(str(c)) <= 1 for c in spec.traj.args)
            else did_you_mean(str(unknown[0]), TRAJ_COLUMNS)
        )
        known = ", ".join(sorted(TRAJ_COLUMNS))
        raise ConfigError(f"traj args: unknown column(s) {unknown}.{hint} Known columns: {known}.")
    for species in spec.species:
        if species.style == "multisphere":
            require("multisphere", "multisphere particles")
        if species.radius.kind != "constant":
            require("polydisperse", "size distributions")
        if species.material.get("cohesionEnergyDensity", 0) > 0:
            require("cohesion", "cohesion")
        if species.material.get("coefficientRollingFriction", 0) > 0:  # cdt, or its own model
            if model.rolling == "cdt":
                require("rolling-friction", "rolling friction")
            else:
                require(f"rolling-{model.rolling}", f"the rolling-friction model {model.rolling}")


def check_run_size(spec: SimulationSpec, step: int, nsteps: int, monitors: Iterable[MonitorSpec]) -> None:
    """Refuse, before it starts, a run whose step count overflows the step counters, whose
    trajectory frames cannot fit on the output's disk (at :data:`FRAME_BYTES` each, however
    few the particles) or whose monitor samples cannot fit in memory."""
    if step + nsteps > MAX_STEP:
        raise ConfigError(
            f"run nsteps={nsteps} would take the simulation past step {MAX_STEP}, the most the step "
            "counters hold: run fewer steps"
        )
    traj = spec.traj
    files = sum(path is not None for path in (traj.pfile, traj.mfile, traj.cfile))
    frames = files * (nsteps // traj.freq)
    free = shutil.disk_usage(spec.output).free
    if frames * FRAME_BYTES > free:
        raise ConfigError(
            f"run nsteps={nsteps} would write {frames:.3g} trajectory frames (traj freq {traj.freq}), at "
            f"least {frames * FRAME_BYTES / 1e9:.3g} GB, but {free / 1e9:.3g} GB are free on the disk of "
            f"{spec.output}: run fewer steps or raise traj freq"
        )
    samples = sum(nsteps // m.freq * (2 + len(m.quantities)) for m in monitors)
    memory = available_memory()
    if samples * SAMPLE_BYTES > memory:
        raise ConfigError(
            f"run nsteps={nsteps} would keep {samples:.3g} monitor values in memory, about "
            f"{samples * SAMPLE_BYTES / 1e9:.3g} GB, but {memory / 1e9:.3g} GB are free: run fewer "
            "steps or raise the monitors' freq"
        )


def outflow_faces(spec: SimulationSpec, faces: Iterable[str]) -> frozenset[str]:
    """The faces (see :data:`FACES`) particles are declared to leave through, checked: a face of
    a periodic axis is refused."""
    for face in faces:
        if face not in FACES:
            raise unknown_key("outflow face", str(face), FACES)
        if spec.domain.periodic["xyz".index(face[0])]:
            raise ConfigError(f"outflow face {face!r}: the {face[0]} axis is periodic, nothing leaves there")
    return frozenset(faces)


def check_servo_speeds(spec: SimulationSpec, dt: float) -> None:
    """LIGGGHTS' limit on servo walls, for every engine that has them: ``vel_max`` below
    half the neighbour skin per step (a wall must not cross the skin between rebuilds)."""
    limit = spec.skin / (2 * dt)
    for mesh in spec.meshes:
        if mesh.servo is not None and not mesh.servo.vel_max < limit:
            raise ConfigError(
                f"mesh {mesh.name!r}: servo vel_max {mesh.servo.vel_max:g} m/s must be below "
                f"skin / (2 dt) = {limit:g} m/s (a servo wall moves at most half the neighbour "
                "skin per step, as on LIGGGHTS): lower vel_max or dt, or raise nns_skin"
            )


def check_servos_are_walls(spec: SimulationSpec, walls: Collection[str | None]) -> None:
    """Refuse a run while a servo mesh is not among the mesh walls ``walls``: its controller
    moves it by the particles' force on it."""
    idle = [m.name for m in spec.meshes if m.servo and m.name not in walls]
    if idle:
        raise ConfigError(
            f"servo mesh {idle[0]!r} must be a wall while the simulation runs (its controller moves it "
            f"by the particles' force on it): setupWall(wtype='mesh', mesh={idle[0]!r}) before run()"
        )


def check_ids(ids: Iterable[int], present: np.ndarray) -> None:
    """Refuse particle ``ids`` (of ``set``) that no particle ``present`` (their ids) has."""
    missing = sorted(set(ids) - set(present.tolist()))
    if missing:
        have = f"ids {present.min()} to {present.max()}" if len(present) else "no particles"
        raise ConfigError(
            f"set/velocity ids: no particle has id {', '.join(map(str, missing[:10]))}"
            f"{' ...' if len(missing) > 10 else ''} "
            f"(the simulation has {len(present)} particles, {have})"
        )


def _point(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{float(c):.6g}" for c in x) + ")"


def check_clear(spec: SimulationSpec, request: CreateSpec, present: np.ndarray, radii: np.ndarray) -> None:
    """Refuse ``single`` positions or lattice sites of ``request`` that overlap each other or the
    particles ``present`` (centres, ``radii``) by more than :data:`CREATE_OVERLAP_TOLERANCE` of
    the smaller radius: they would repel at high speed."""
    from scipy.spatial import cKDTree

    centres = request.centres
    radius = request.radius or spec.species[request.species - 1].radius.min
    # every close pair: (index of the new centre, the other's centre, its radius, the gap)
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    if len(present):
        reach = radius + float(radii.max())
        if len(present) * len(centres) <= 1_000_000:
            gaps = np.linalg.norm(present[None, :, :] - centres[:, None, :], axis=2)
            new, old = np.nonzero(gaps < reach)
            gap = gaps[new, old]
        else:
            near = cKDTree(centres).sparse_distance_matrix(cKDTree(present), reach, output_type="ndarray")
            new, old, gap = near["i"], near["j"], near["v"]
        found.append((new, present[old], radii[old], gap))
    if len(centres) > 1:
        among = cKDTree(centres).query_pairs(2 * radius, output_type="ndarray").reshape(-1, 2)
        gap = np.linalg.norm(centres[among[:, 0]] - centres[among[:, 1]], axis=1)
        found.append((among[:, 1], centres[among[:, 0]], np.full(len(among), radius), gap))
    if not found:
        return
    new, others, sizes, gap = (np.concatenate(parts) for parts in zip(*found))
    depth = (sizes + radius - gap) / np.minimum(sizes, radius)
    if not len(depth) or depth.max() <= CREATE_OVERLAP_TOLERANCE:
        return
    worst = int(np.argmax(depth))
    kind = "the particle present" if worst < len(found[0][0]) and len(present) else "the new one"
    raise ConfigError(
        f"createParticles position {_point(centres[new[worst]])} overlaps {kind} at "
        f"{_point(others[worst])} by {100 * min(depth[worst], 2.0):.3g} % of the smaller "
        f"radius ({int((depth > CREATE_OVERLAP_TOLERANCE).sum())} overlapping pairs in all): "
        "overlapping particles repel at high speed. Move the positions apart, at least the sum of "
        "the radii."
    )


# -- the time step ------------------------------------------------------------------------------


def species_present(spec: SimulationSpec, types: np.ndarray, radii: np.ndarray) -> Present:
    """(species, smallest radius, whether more than one) of the particles of ``types`` and ``radii``."""
    types = types.astype(np.int64)
    kinds = [int(k) for k in np.unique(types) if 1 <= k <= len(spec.species)]
    return tuple((k, float(radii[types == k].min()), int(np.count_nonzero(types == k)) > 1) for k in kinds)


class TimeStepLimits:
    """The shortest Rayleigh and contact times of the contacts that can happen in a simulation
    of ``spec``, cached by what they depend on: between the species present (two particles of
    one) or being inserted, and of them with every wall's material."""

    def __init__(self, spec: SimulationSpec) -> None:
        self.spec = spec
        self._found: dict[tuple[object, ...], Limits | None] = {}
        self._warned: set[tuple[float, Limits]] = set()

    def __call__(self, present: Present, coming: Collection[int], walls: Iterable[WallSpec]) -> Limits | None:
        """The limits with the particles ``present``, the species ``coming`` (being inserted)
        and the ``walls``."""
        species = self.spec.species
        smallest = {k: r for k, r, _ in present}
        several = {k for k, _, many in present if many} | set(coming)
        for kind in coming:
            smallest[kind] = min(smallest.get(kind, math.inf), species[kind - 1].radius.min)
        materials = {}
        for wall in walls:
            mesh = next((m for m in self.spec.meshes if m.name == wall.mesh and m.material), None)
            if mesh is not None:
                materials[f"mesh {mesh.name!r}"] = mesh.material
            else:
                materials[f"walls of species {wall.species}'s material"] = species[wall.species - 1].material
        key = (tuple(sorted((k, r, k in several) for k, r in smallest.items())), tuple(sorted(materials)))
        if key not in self._found:
            bodies = {
                k: Body(f"species {k}", species[k - 1].material, r, species[k - 1].density)
                for k, r in smallest.items()
            }
            pairs = [
                (bodies[a], bodies[b]) for a in bodies for b in bodies if a < b or (a == b and a in several)
            ]
            pairs += [
                (body, Body(name, material))
                for body in bodies.values()
                for name, material in materials.items()
            ]
            everything = [s.material for s in species] + [m.material for m in self.spec.meshes if m.material]
            self._found[key] = limits(self.spec.model, pairs, characteristic_speed(everything))
        return self._found[key]

    def judge(
        self, dt: float, present: Present, coming: Collection[int], walls: Iterable[WallSpec], check_dt: bool
    ) -> tuple[Assessment | None, str | None, str | None]:
        """``dt`` against these limits (see :meth:`__call__`): the assessment (``None``: no
        contact can happen), why a run of it is refused (one that cannot resolve the contacts,
        unless not ``check_dt``) and the warning due (once per time step and set of contacts)."""
        found = self(present, coming, walls)
        check = None if found is None else found.assess(dt)
        if found is None or check is None or check.level == "ok":
            return check, None, None
        if check.level == "error" and check_dt:
            return check, f"{check.message()} Or pass check_dt=False to run() to run anyway.", None
        new = (dt, found) not in self._warned
        self._warned.add((dt, found))
        return check, None, check.message() if new else None


# -- lost particles ------------------------------------------------------------------------------


def exit_faces(spec: SimulationSpec, x: np.ndarray, v: np.ndarray, duration: float) -> list[str]:
    """The face of the box (``"z-"``, ...) each particle at ``x`` moving at ``v`` reaches first
    when it moves so, with gravity, for ``duration``; ``"non-finite"`` or ``"unknown"`` if none."""
    box = np.array(spec.domain.box, float)
    fixed = ~np.array(spec.domain.periodic)
    gravity = spec.gravity.vector if spec.gravity is not None else np.zeros(3)
    lo, hi = box[:, 0], box[:, 1]
    places = []
    for position, step in zip(x, v * duration + 0.5 * gravity * duration**2):
        if not (np.isfinite(position).all() and np.isfinite(step).all()):
            places.append("non-finite")
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = np.where(step > 0, hi, lo)
            reach = np.where(fixed & (step != 0), (bound - position) / step, np.inf)
        outside = fixed & ((position < lo) | (position > hi))
        if outside.any():
            axis = int(np.flatnonzero(outside)[0])
            places.append("xyz"[axis] + ("-" if position[axis] < lo[axis] else "+"))
        elif np.isfinite(reach).any():
            axis = int(np.argmin(reach))
            places.append("xyz"[axis] + ("+" if step[axis] > 0 else "-"))
        else:
            places.append("unknown")
    return places


class LostWatch:
    """Lost particles of an engine that does not report them, over one run: those gone by its
    end, placed at the face their position and velocity at its start (and gravity) were
    heading for, and those still present whose position or velocity has become non-finite,
    each counted once (``broken``: the ids of those counted before, kept across runs)."""

    def __init__(
        self, spec: SimulationSpec, extract: Callable[[str], np.ndarray], time: float, broken: set[int]
    ) -> None:
        self.spec, self.extract, self.start, self.broken = spec, extract, time, broken
        self.ids, self.x, self.v = self._state()

    def _state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.extract("id"), self.extract("x").reshape(-1, 3), self.extract("v").reshape(-1, 3)

    def finish(self, time: float) -> LostParticles:
        """What was lost between the start of the run and ``time``."""
        ids, x, v = self._state()
        gone = ~np.isin(self.ids, ids)
        where: dict[str, int] = {}
        for place in exit_faces(self.spec, self.x[gone], self.v[gone], time - self.start):
            where[place] = where.get(place, 0) + 1
        broken = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        fresh = [i for i in ids[broken].tolist() if i not in self.broken]
        self.broken.update(fresh)
        if fresh:
            where["non-finite"] = where.get("non-finite", 0) + len(fresh)
        return LostParticles(int(gone.sum()) + len(fresh), where)  # speeds when lost: unknown


def lost_report(
    engine: str,
    spec: SimulationSpec,
    lost: LostParticles,
    estimated: bool,
    run: tuple[int, int],
    outflow: frozenset[str],
    total: int,
    check: Assessment | None,
    given_speed: float,
    speeds: np.ndarray,
) -> tuple[str | None, str | None]:
    """What to log of the particles ``lost`` in the ``run`` (first and last step) of the
    ``engine`` engine through the expected ``outflow``, and the warning about the others, with
    their likely cause (:func:`lost_cause`) and the ``total`` lost so far; ``None`` where there
    is nothing to say. ``estimated``: found missing, not counted by the engine."""
    expected = sum(n for place, n in lost.where.items() if place in outflow)
    logged = None
    if expected:
        logged = (
            f"{expected} particle{'' if expected == 1 else 's'} left through the expected outflow "
            f"({', '.join(sorted(outflow))}) in the run from step {run[0]} to {run[1]}"
        )
    if expected == lost.count:
        return logged, None
    unexpected = lost.count - expected
    how = (
        f" (as the {engine} engine does not report lost particles, PyGran found them missing and "
        "estimated where from where they were last seen)"
        if estimated
        else ""
    )
    cause = lost_cause(spec, lost, check, given_speed, speeds, outflow)
    return logged, (
        f"{unexpected} particle{'s' if unexpected > 1 else ''} lost in the run from step {run[0]} to "
        f"{run[1]}: {lost.places(outflow)}{how}; {cause}. {total} lost in all."
    )


def lost_cause(
    spec: SimulationSpec,
    lost: LostParticles,
    check: Assessment | None,
    given_speed: float,
    speeds: np.ndarray,
    outflow: frozenset[str],
) -> str:
    """The likely cause of ``lost``: from their speeds and the ``speeds`` of the particles left
    (an instability throws both far faster than the simulation explains: its characteristic
    velocity, the fastest speed the script gave, ``given_speed``, or a fall across the box),
    non-finite values, the time-step ``check`` and the faces they left through that are no
    expected ``outflow``."""
    step = (
        f"the time step is probably too large: {check.times()}; use dt <= {check.limits.safe_dt:.2g} s"
        if check is not None and check.level != "ok"
        else None
    )
    box = spec.domain.lengths
    fall = math.sqrt(2 * spec.gravity.magnitude * float(box.max())) if spec.gravity else 0.0
    explained = max(given_speed, fall, characteristic_speed([s.material for s in spec.species]))
    fastest = max(lost.max_speed or 0.0, float(speeds[np.isfinite(speeds)].max(initial=0.0)))
    fast = fastest > FAST_FACTOR * explained
    if fast or lost.where.get("non-finite"):
        seen = (
            f"speeds up to {fastest:.3g} m/s, over {FAST_FACTOR:g} times the {explained:.3g} m/s the "
            "simulation explains"
            if fast
            else "non-finite positions or velocities"
        )
        return f"{seen}: " + (
            step
            or "particles probably started overlapping (created on top of each other or with a lattice "
            "spacing below a diameter) or inside a wall"
        )
    faces = sorted(place for place in lost.where if place in FACES and place not in outflow)
    if faces:
        at = f" at up to {lost.max_speed:.3g} m/s" if lost.max_speed is not None else ""
        went = f"they left{at} through {', '.join(faces)}"
        if step is not None:
            return f"{went} (a contact too short to resolve lets particles pass through walls): {step}"
        return (
            f"{went}, where no wall holds them: add a wall inside the box, or declare an opening "
            f"with expect_outflow({', '.join(map(repr, faces))})"
        )
    return step or "look for particles created outside the box or beyond a wall"


# -- servo walls ----------------------------------------------------------------------------------


def force_servos(spec: SimulationSpec) -> dict[str, ServoSpec]:
    """The servo walls controlled by force, by mesh name."""
    return {m.name: m.servo for m in spec.meshes if m.servo is not None and m.servo.control == "force"}


def servo_error(servo: ServoSpec, force: np.ndarray) -> float:
    """The servo's relative error with ``force`` on its wall: (the force pushing back along its
    axis - target) / target."""
    axis = np.asarray(servo.axis, float) / np.linalg.norm(servo.axis)
    return float((-(force @ axis) - abs(servo.target)) / abs(servo.target))


def servo_swing(name: str, servo: ServoSpec, errors: list[float]) -> str | None:
    """Why servo wall ``name`` does not settle, if its force swung about its target by more than
    :data:`SERVO_SWING` of it at each of the run's last :data:`SERVO_WATCH` + 1 readings
    ``errors`` (one step apart, see :func:`servo_error`); else ``None``."""
    swinging = len(errors) == SERVO_WATCH + 1 and all(
        a * b < 0 and min(abs(a), abs(b)) > SERVO_SWING for a, b in itertools.pairwise(errors)
    )
    if not swinging:
        return None
    shown = ", ".join(f"{1 + e:.3g}" for e in errors)
    return (
        f"servo wall {name!r} does not settle: the force on it swings about its target from step "
        f"to step ({shown} times the target at the run's last {len(errors)} steps). The "
        f"controller (LIGGGHTS', kp={servo.kp:g}, vel_max={servo.vel_max:g} m/s) is unstable on "
        "this bed: the plate's own speed, through the contacts' damping, overturns the force each "
        "step. Lower kp or vel_max (by 2 or more)."
    )


class RunWatch:
    """What one run (from step ``start`` to ``end``) is watched for: the particles it loses, as
    the engine counts them (``lost_since_last``) or, if it does not, found missing by a
    :class:`LostWatch`; and the force on its force servo walls (``force``, by mesh name; ``None``
    without servo walls) at each of its last :data:`SERVO_WATCH` + 1 steps."""

    def __init__(
        self,
        spec: SimulationSpec,
        start: int,
        end: int,
        time: float,
        extract: Callable[[str], np.ndarray],
        lost_since_last: Callable[[], LostParticles | None],
        broken: set[int],
        force: Callable[[str], np.ndarray] | None,
    ) -> None:
        counted = lost_since_last()
        self._count = lost_since_last
        self._missing = LostWatch(spec, extract, time, broken) if counted is None else None
        self._lost = counted or LostParticles()
        self._servos = force_servos(spec) if force is not None else {}
        self._errors: dict[str, list[float]] = {name: [] for name in self._servos}
        self._force = force
        self._start, self._end = start, end

    def after_piece(self, step: int) -> None:
        """Take what is watched after the piece of the run that ended at ``step``."""
        if self._missing is None:
            self._lost += self._count() or LostParticles()
        if (
            self._force is not None
            and self._end - self._start > SERVO_WATCH
            and step >= self._end - SERVO_WATCH
        ):
            for name, errors in self._errors.items():
                try:
                    errors.append(servo_error(self._servos[name], self._force(name)))
                except ConfigError:  # not a wall (yet): nothing to judge
                    errors.append(0.0)

    def lost(self, time: float) -> tuple[LostParticles, bool]:
        """The particles lost in the run, ended at ``time``, and whether they were found missing
        (where they went estimated) rather than counted by the engine."""
        if self._missing is not None:
            return self._missing.finish(time), True
        return self._lost, False

    def servo_warnings(self) -> list[str]:
        """Why the servo walls whose force swung about its target do not settle."""
        found = (servo_swing(name, self._servos[name], errors) for name, errors in self._errors.items())
        return [message for message in found if message is not None]
