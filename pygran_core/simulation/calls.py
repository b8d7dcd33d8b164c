"""Validated requests for the calls a simulation takes after it is set up.

Each ``parse_*`` function turns the keywords of one ``simulation.DEM`` method (manual,
section 4.2) into a frozen record that engines map onto their solver.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np

from pygran_core.errors import ConfigError, did_you_mean, unknown_key
from pygran_core.simulation import geometry
from pygran_core.simulation.specs import (
    BOX_TOLERANCE,
    SimulationSpec,
    Vector,
    check_keys,
    check_radius,
    finite_number,
    given,
    is_integer,
    is_real,
    number_tuple,
    one_of,
    positive_float,
    positive_int,
    step_count,
    vector,
)

# -- regions ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Region:
    """A region of space: ``block`` (xlo, xhi, ylo, yhi, zlo, zhi), ``cylinder`` (axis, c1,
    c2, radius, lo, hi: LIGGGHTS order, the axis one of x/y/z), ``cone`` (axis, c1, c2, radlo,
    radhi, lo, hi: LIGGGHTS' order), ``sphere`` (x, y, z, r), ``mesh`` (a closed
    :class:`~pygran_core.simulation.geometry.Surface`: its inside) or ``intersect`` (regions:
    the points inside all of them)."""

    kind: str
    args: tuple[Any, ...]

    def __str__(self) -> str:
        """As a script gives it: ``('block', 0, 0.01, 0, 0.01, 0, 0.02)``."""

        def word(a: Any) -> str:
            if isinstance(a, Region):
                return str(a)
            return repr(a) if isinstance(a, (str, geometry.Surface)) else f"{a:g}"

        words = [word(a) for a in (self.kind, *self.args)]
        return f"({', '.join(words)})"

    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box, shape (3, 2)."""
        if self.kind == "block":
            return np.array(self.args, float).reshape(3, 2)
        if self.kind == "sphere":
            centre, radius = np.array(self.args[:3]), self.args[3]
            return np.column_stack([centre - radius, centre + radius])
        if self.kind == "mesh":
            return np.array(self.args[0].bounds)
        if self.kind == "intersect":
            parts = np.stack([part.bounds() for part in self.args])
            return np.column_stack([parts[:, :, 0].max(axis=0), parts[:, :, 1].min(axis=0)])
        axis, c1, c2, *radii, lo, hi = self.args
        radius = max(radii)
        along = "xyz".index(axis)
        across = [i for i in range(3) if i != along]
        out = np.empty((3, 2))
        out[along] = lo, hi
        out[across[0]] = c1 - radius, c1 + radius
        out[across[1]] = c2 - radius, c2 + radius
        return out

    def volume(self) -> float:
        """In m^3; of an intersection, estimated from 20,000 points (seeded: always the same; a
        standard error of 0.3 % for an intersection filling three quarters of its bounds)."""
        if self.kind == "block":
            return float(np.prod(np.diff(self.bounds(), axis=1)))
        if self.kind == "sphere":
            return 4.0 / 3.0 * math.pi * self.args[3] ** 3
        if self.kind == "mesh":
            return self.args[0].volume
        if self.kind == "intersect":
            box = self.bounds()
            points = np.random.default_rng(0).uniform(box[:, 0], box[:, 1], (20_000, 3))
            return float(np.prod(box[:, 1] - box[:, 0]) * np.mean(self.contains(points)))
        if self.kind == "cone":
            _, _, _, r1, r2, lo, hi = self.args
            return math.pi * (hi - lo) * (r1 * r1 + r1 * r2 + r2 * r2) / 3
        _, _, _, radius, lo, hi = self.args
        return math.pi * radius**2 * (hi - lo)

    def contains(self, points: np.ndarray, margin: float | np.ndarray = 0.0) -> np.ndarray:
        """Which ``points`` (n, 3) lie inside, at least ``margin`` (per point) from the surface."""
        points = np.asarray(points, float)
        margin = np.asarray(margin, float)
        if self.kind == "block":
            box = self.bounds()
            return np.all(
                (points >= box[:, 0] + margin[..., None]) & (points <= box[:, 1] - margin[..., None]), axis=1
            )
        if self.kind == "sphere":
            return np.linalg.norm(points - np.array(self.args[:3]), axis=1) <= self.args[3] - margin
        if self.kind == "mesh":
            return self.args[0].contains(points, margin)
        if self.kind == "intersect":  # the meshes last, on the points the primitives keep
            inside = np.ones(len(points), bool)
            margins = np.broadcast_to(margin, (len(points),))
            for part in sorted(self.args, key=lambda part: part.kind == "mesh"):
                inside[inside] = part.contains(points[inside], margins[inside])
            return inside
        axis, c1, c2, *radii, lo, hi = self.args
        along = "xyz".index(axis)
        across = [i for i in range(3) if i != along]
        r = np.hypot(points[:, across[0]] - c1, points[:, across[1]] - c2)
        z = points[:, along]
        if self.kind == "cone":  # the distance to the slanted side is the radial gap times cos(slope)
            r_lo, r_hi = radii
            radius = r_lo + (r_hi - r_lo) * (z - lo) / (hi - lo)
            slope = math.cos(math.atan2(abs(r_hi - r_lo), hi - lo))
            return ((radius - r) * slope >= margin) & (z >= lo + margin) & (z <= hi - margin)
        return (r <= radii[0] - margin) & (z >= lo + margin) & (z <= hi - margin)


REGION_ARITY = {"block": 6, "cylinder": 6, "cone": 7, "sphere": 4}


def _face_flag(spec: SimulationSpec, axis: int, side: int) -> str:
    """The boundary flag of the lower (``side`` 0) or upper (1) face of ``axis``."""
    flag = spec.domain.boundary[axis]
    return flag[0] if side == 0 else flag[-1]


def _limits(spec: SimulationSpec) -> tuple[np.ndarray, float]:
    box = np.array(spec.domain.box, float)
    return box, BOX_TOLERANCE * float(np.max(box[:, 1] - box[:, 0]))


def _box_text(spec: SimulationSpec) -> str:
    return ", ".join(f"{axis} {lo:g} to {hi:g}" for axis, (lo, hi) in zip("xyz", spec.domain.box))


def check_region_in_box(region: Region, spec: SimulationSpec, call: str) -> None:
    """Refuse a region of ``call`` (``insert``, ``createParticles``) reaching beyond a face of the
    box that is not shrink-wrapped: beyond a fixed face the particles placed there are lost at
    once (LIGGGHTS refuses such an insertion region); beyond a periodic face they would be wrapped
    onto places no overlap check looked at."""
    box, tol = _limits(spec)
    bounds = region.bounds()
    for axis in range(3):
        for side, beyond in (
            (0, bounds[axis, 0] < box[axis, 0] - tol),
            (1, bounds[axis, 1] > box[axis, 1] + tol),
        ):
            flag = _face_flag(spec, axis, side)
            if not beyond or flag in ("s", "m"):
                continue
            face = "periodic" if flag == "p" else "fixed"
            raise ConfigError(
                f"{call} region {region} reaches {'xyz'[axis]} = "
                f"{bounds[axis, side]:g}, beyond the box's {face} {'xyz'[axis]}{'-+'[side]} face at "
                f"{box[axis, side]:g} (box: {_box_text(spec)}): keep the region inside the box"
                + (", or make that face shrink-wrapped (boundary 's')" if flag == "f" else "")
            )


def check_points_in_box(points: np.ndarray, spec: SimulationSpec, what: str) -> None:
    """Refuse centres outside the box, on any axis (LIGGGHTS' ``create_atoms single`` creates
    nothing there, and a fixed face loses them)."""
    box, tol = _limits(spec)
    outside = np.any((points < box[:, 0] - tol) | (points > box[:, 1] + tol), axis=1)
    if outside.any():
        first = points[np.flatnonzero(outside)[0]]
        where = ", ".join(f"{v:g}" for v in first)
        raise ConfigError(
            f"{what} ({where}) is outside the box ({_box_text(spec)})"
            + (
                f", as are {int(outside.sum()) - 1} more of the {len(points)} positions"
                if outside.sum() > 1
                else ""
            )
            + ": give positions inside the box, or a larger box"
        )


def parse_region(value: Any, spec: SimulationSpec) -> Region:
    """``('block', xlo, ...)`` and friends; ``None`` or ``'sim_box'`` is the whole box; a
    closed surface, or ``('mesh', surface or the name of a mesh)``, is its inside;
    ``('intersect', region, region, ...)`` the points inside all of them."""
    if value is None or isinstance(value, str) and value == "sim_box":
        return Region("block", tuple(v for pair in spec.domain.box for v in pair))
    if isinstance(value, geometry.Surface):
        value = ("mesh", value)
    if isinstance(value, str) or not isinstance(value, Sequence) or not value:
        raise ConfigError(
            f"region must be a tuple such as ('block', xlo, xhi, ylo, yhi, zlo, zhi): {value!r}"
        )
    kind = one_of(value[0], "region type", [*REGION_ARITY, "mesh", "intersect"])
    if kind == "mesh":
        return _mesh_region(value, spec)
    if kind == "intersect":
        if len(value) < 3:
            raise ConfigError(f"an 'intersect' region needs two regions or more: {value!r}")
        region = Region(kind, tuple(parse_region(part, spec) for part in value[1:]))
        if np.any(np.diff(region.bounds()) <= 0):
            raise ConfigError(f"the regions of {region} do not overlap: their intersection is empty")
        return region
    args = tuple(value[1:])
    if len(args) == 1 and isinstance(args[0], str):  # PyGran 1.x: ('block', '-1e-3 1e-3 ...')
        args = tuple(float(word) if _is_number(word) else word for word in args[0].split())
    elif len(args) == 1 and isinstance(args[0], Sequence):  # ('block', (xlo, xhi, ...))
        args = tuple(args[0])
    if len(args) != REGION_ARITY[kind]:
        raise ConfigError(f"region {kind!r} takes {REGION_ARITY[kind]} values, got {len(args)}: {value!r}")
    if kind == "cylinder":
        axis = one_of(args[0], "cylinder axis", ("x", "y", "z"))
        numbers = tuple(finite_number(v, "cylinder region") for v in args[1:])
        if numbers[2] <= 0 or numbers[3] >= numbers[4]:
            raise ConfigError(f"cylinder region needs radius > 0 and lo < hi: {value!r}")
        return Region(kind, (axis, *numbers))
    if kind == "cone":
        axis = one_of(args[0], "cone axis", ("x", "y", "z"))
        numbers = tuple(finite_number(v, "cone region") for v in args[1:])
        if min(numbers[2:4]) < 0 or max(numbers[2:4]) <= 0 or numbers[4] >= numbers[5]:
            raise ConfigError(f"cone region needs radii >= 0 (one > 0) and lo < hi: {value!r}")
        return Region(kind, (axis, *numbers))
    numbers = tuple(finite_number(v, f"{kind} region") for v in args)
    region = Region(kind, numbers)
    if kind == "sphere" and numbers[3] <= 0 or kind == "block" and np.any(np.diff(region.bounds()) <= 0):
        raise ConfigError(f"region {value!r} is empty")
    return region


def _mesh_region(value: Sequence[Any], spec: SimulationSpec) -> Region:
    """``('mesh', surface)``, ``('mesh', triangles)`` or ``('mesh', name)`` of a mesh of the
    simulation: the inside of a closed surface."""
    if len(value) != 2:
        raise ConfigError(f"a 'mesh' region takes one surface or mesh name: {value!r}")
    given = value[1]
    if isinstance(given, str):
        known = {mesh.name: mesh for mesh in spec.meshes}
        if given not in known:
            raise unknown_key("mesh of the region", given, list(known))
        surface = geometry.Surface(known[given].triangles(), given, known[given].inscribed)
    else:
        surface = geometry.as_surface(given, "of the region")
    surface.require_closed("an insertion region")
    return Region("mesh", (surface,))


# -- species selection, velocities --------------------------------------------------------


def parse_species_selection(value: Any, spec: SimulationSpec) -> tuple[int, ...]:
    """``'all'`` or a species number (1-based) or a sequence of them."""
    known = tuple(s.type for s in spec.species)
    if not known:
        raise ConfigError("No species defined: pass species=({'material': ..., 'radius': ...},) to DEM")
    if isinstance(value, str) and value == "all":
        return known
    chosen = (value,) if isinstance(value, Integral) else value
    if isinstance(chosen, str) or not isinstance(chosen, Sequence) or not chosen:
        raise ConfigError(
            f"species must be 'all', a species number or numbers; defined: {known}, got {value!r}"
        )
    for item in chosen:
        if not is_integer(item) or item not in known:
            raise ConfigError(f"species {item!r} does not exist; defined species: {known} or 'all'")
    return tuple(int(i) for i in chosen)


@dataclass(frozen=True)
class VelocityDistribution:
    """Initial velocities: ``constant`` ``mean``, or ``uniform``/``gaussian`` with ``spread``."""

    kind: str = "constant"
    mean: Vector = (0.0, 0.0, 0.0)
    spread: Vector = (0.0, 0.0, 0.0)

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        mean, spread = np.array(self.mean), np.array(self.spread)
        if self.kind == "uniform":
            return mean + spread * rng.uniform(-1.0, 1.0, (count, 3))
        if self.kind == "gaussian":
            return mean + spread * rng.standard_normal((count, 3))
        return np.tile(mean, (count, 1))


def parse_velocity(kind: Any, values: Any) -> VelocityDistribution:
    kind = one_of(str(kind).lower(), "vel_type", ("constant", "uniform", "gaussian"))
    size = 3 if kind == "constant" else 6
    numbers = number_tuple(values, f"vel ({kind})", size)
    spread = vector(numbers[3:], "vel spread") if size == 6 else (0.0, 0.0, 0.0)
    return VelocityDistribution(kind, vector(numbers[:3], "vel mean"), spread)


# -- insert ------------------------------------------------------------------------------------

PACK_TARGETS = ("particles_in_region", "volumefraction_region", "mass_in_region")
RATE_TARGETS = ("particlerate", "massrate")
#: PyGran 1.x's totals of an insertion by rate (``mech``) and the rate each goes with.
RATE_TOTALS = {"nparticles": "particlerate", "mass": "massrate"}


@dataclass(frozen=True)
class InsertSpec:
    """Insert particles of ``species`` (number fractions ``weights``) into ``region``.

    ``by_pack``: once (or every ``freq`` steps) until the region holds ``value`` particles,
    volume fraction or mass (``target``). ``by_rate``: ``value`` particles or kg per second
    (``target``), every ``freq`` steps, for ``duration`` seconds (``None``: until removed).
    ``requested`` is the amount the script asked for: for ``particles_in_region`` it comes on
    top of the particles in the region at the call (PyGran 1.x added them), so ``value`` is
    their sum. A volume fraction may be up to 1: the region gets what fits.

    Insertion ``k`` is due at step ``first + k * freq`` (see :func:`~.insertion.insertion_steps`)
    and is made as the step after it starts: a run's last step inserts nothing, the next run
    does so as it starts, as LIGGGHTS does. Multisphere species take an ``orientation``:
    ``'random'``, ``'template'`` or ``('constant', q1, q2, q3, q4)``.
    """

    mechanism: str
    target: str
    value: float = field(repr=False)
    species: tuple[int, ...]
    weights: tuple[float, ...]
    region: Region
    velocity: VelocityDistribution
    omega: Vector = (0.0, 0.0, 0.0)
    freq: int | None = None
    duration: float | None = None
    all_in: bool = True
    seed: int = 0
    requested: float | None = None
    orientation: str | tuple[float, float, float, float] | None = None


INSERT_KEYS = (
    "species",
    "value",
    "insert",
    "mech",
    "region",
    "vel_type",
    "vel",
    "omega",
    "freq",
    "all_in",
    "rate",
    "rate_type",
    "weights",
    "duration",
    "seed",
    "orientation",
    "set_property",
    "args",
)
#: Random close packing of monodisperse spheres: a volume fraction above it cannot be reached.
CLOSE_PACKING = 0.64
#: Memory one particle takes in an engine (bytes), with its share of the neighbour lists and
#: contact histories: what a request for particles is checked against before any is made.
PARTICLE_BYTES = 1000


def available_memory() -> int:
    """Bytes of memory free for a new allocation now (Linux' MemAvailable), else the
    machine's physical memory."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_memory(count: float, call: str) -> None:
    """Refuse ``count`` particles whose memory (:data:`PARTICLE_BYTES` each) is not free."""
    need, free = count * PARTICLE_BYTES, available_memory()
    if need > free:
        raise ConfigError(
            f"{call} asks for {count:.3g} particles, which need about {need / 1e9:.3g} GB of memory "
            f"({PARTICLE_BYTES} bytes each), but {free / 1e9:.3g} GB are free: ask for fewer"
        )


def particle_sizes(species: Sequence[int], spec: SimulationSpec) -> tuple[float, float]:
    """The smallest radius a particle of ``species`` can have (of a multisphere body: its
    largest sphere, which it holds at least) and the farthest any reaches from its centre."""
    smallest = min(spec.species[k - 1].radius.min for k in species)
    reaches = [
        max((math.hypot(*sphere[:3]) + sphere[3] for sphere in sp.spheres), default=sp.radius.max)
        for sp in (spec.species[k - 1] for k in species)
    ]
    return smallest, max(reaches)


def check_packing(
    amount: float, each: float, region: Region, call: str, unit: str, sizes: tuple[float, float], all_in: bool
) -> None:
    """Refuse ``amount`` (in ``unit``, each unit ``each`` m^3 of solid at least; ``sizes``
    from :func:`particle_sizes`) that no engine could place in ``region``, and trying would not
    end. ``all_in`` (whole particles inside): a region thinner than the smallest particle, or
    beyond random close packing of its volume; centres only inside: beyond random close
    packing of its bounding box grown by the farthest reach (more room than they can fill)."""
    smallest, reach = sizes
    extents = np.diff(region.bounds(), axis=1).ravel()
    if all_in and extents.min() < 2 * smallest:
        raise ConfigError(
            f"{call}: no particle fits wholly inside the region {region}: it is {extents.min():.3g} m "
            f"across at its thinnest, less than the smallest particle's diameter {2 * smallest:.3g} m; "
            "give a larger region" + (", or all_in='no' (centres inside)" if call == "insert" else "")
        )
    volume = region.volume() if all_in else float(np.prod(extents + 2 * reach))
    room = CLOSE_PACKING * volume
    if amount * each > room:
        raise ConfigError(
            f"{call}: {amount:.6g} {unit} cannot fit in the region {region}: they fill at least "
            f"{amount * each:.3g} m^3, above the {room:.3g} m^3 spheres can fill of its {volume:.3g} m^3 "
            f"{'' if all_in else 'reached by particles centred in it '}(random close packing, "
            f"{CLOSE_PACKING}): ask for at most {room / each:.6g} {unit}, or give a larger region"
        )


def _seed(value: Any, call: str) -> int:
    if not is_integer(value) or value < 0:
        raise ConfigError(f"{call} seed must be a non-negative integer, got {value!r}")
    return int(value)


def _flag(value: Any, name: str) -> bool:
    if value is True or isinstance(value, str) and value == "yes":
        return True
    if value is False or isinstance(value, str) and value == "no":
        return False
    raise ConfigError(f"{name} must be 'yes' or 'no', got {value!r}")


def parse_orientation(value: Any, species: Sequence[int], spec: SimulationSpec) -> Any:
    """A multisphere insertion's orientation: ``'random'``, ``'template'`` or
    ``('constant', q1, q2, q3, q4)`` (a unit quaternion); spheres take none."""
    spheres = [k for k in species if spec.species[k - 1].style == "sphere"]
    if spheres:
        raise ConfigError(
            f"insert orientation={value!r}: species {spheres[0]} is a sphere, which has no orientation; "
            "leave orientation out (it applies to multisphere species)"
        )
    if value in ("random", "template"):
        return value
    if isinstance(value, str):
        value = value.split()
    if isinstance(value, Sequence) and len(value) == 5 and value[0] == "constant":
        q = np.array(number_tuple(value[1:], "insert orientation quaternion", 4))
        if not math.isclose(float(np.linalg.norm(q)), 1.0, rel_tol=1e-6):
            raise ConfigError(f"insert orientation {value!r}: the quaternion must have length 1")
        return tuple(float(v) for v in q)
    raise ConfigError(
        f"insert orientation must be 'random', 'template' or ('constant', q1, q2, q3, q4), got {value!r}"
    )


def parse_insert(
    kwargs: Mapping[str, Any], spec: SimulationSpec, seed: int, notes: list[str] | None = None
) -> InsertSpec:
    """``insert(species, value, ...)`` (manual 4.2.1); ``args={'orientation': ...}`` is
    PyGran 1.x's way to give multisphere keywords. ``value`` is the amount asked for: see
    :class:`InsertSpec` for how ``particles_in_region`` adds to what is there."""
    check_keys("insert keyword", kwargs, INSERT_KEYS)
    args = kwargs.get("args", {})
    if not isinstance(args, Mapping):
        raise ConfigError(f"insert args must be a dict such as {{'orientation': 'random'}}, got {args!r}")
    check_keys("insert args keyword", args, ("orientation",))
    if "orientation" in args and "orientation" in kwargs:
        raise ConfigError("insert: give orientation once, as orientation= or in args")
    if "set_property" in kwargs:
        raise ConfigError("insert: 'set_property' (a fix property/atom of LIGGGHTS) is not supported")
    mechanism = one_of(kwargs.get("insert", "by_pack"), "insert mechanism", ("by_pack", "by_rate"))
    species = parse_species_selection(kwargs.get("species", "all"), spec)
    weights = kwargs.get("weights", [1.0 / len(species)] * len(species))
    if isinstance(weights, str) or not isinstance(weights, Sequence):
        raise ConfigError(f"insert weights must be {len(species)} fractions summing to 1, got {weights!r}")
    weights = tuple(finite_number(w, "insert weights") for w in weights)
    if len(weights) != len(species) or min(weights) < 0 or not math.isclose(sum(weights), 1.0, rel_tol=1e-6):
        raise ConfigError(f"insert weights {weights} must be {len(species)} fractions summing to 1")
    duration = kwargs.get("duration")
    if mechanism == "by_pack":
        target = one_of(kwargs.get("mech", "particles_in_region"), "insert by_pack mech", PACK_TARGETS)
        value = kwargs.get("value")
    elif isinstance(kwargs.get("mech"), str) and kwargs["mech"] in RATE_TOTALS:  # PyGran 1.x: a total
        if kwargs.get("rate") is None or kwargs.get("value") is None or duration is not None:
            raise ConfigError(
                f"insert by_rate with mech={kwargs['mech']!r}: give the total as value=... and the rate "
                "as rate=... (per second), not duration"
            )
        target = one_of(
            kwargs.get("rate_type", RATE_TOTALS[kwargs["mech"]]), "insert rate_type", RATE_TARGETS
        )
        value = positive_float(kwargs["rate"], "insert rate")
        duration = positive_float(kwargs["value"], "insert value") / value
    else:
        target = one_of(
            kwargs.get("rate_type", kwargs.get("mech", "particlerate")), "insert rate_type", RATE_TARGETS
        )
        value = kwargs.get("rate", kwargs.get("value"))
    if value is None:
        raise ConfigError(f"insert {mechanism}: give the amount as value=... (or rate=... for by_rate)")
    value = positive_float(value, "insert value")
    if target == "volumefraction_region":
        if value > 1:
            raise ConfigError(
                f"insert volumefraction_region {value} is above 1: give a fraction of the region"
            )
        if value > CLOSE_PACKING and notes is not None:
            notes.append(
                f"insert volume fraction {value:g} is above what spheres can fill (random close packing "
                f"~{CLOSE_PACKING}): the region gets what fits"
            )
    if target == "particles_in_region" and value != int(value):
        raise ConfigError(f"insert particles_in_region needs a whole number of particles, got {value}")
    region = _region_in_box(kwargs.get("region"), spec, "insert")
    all_in = _flag(kwargs.get("all_in", "yes"), "insert all_in")
    sizes = particle_sizes(species, spec)
    smallest = 4 / 3 * math.pi * sizes[0] ** 3
    density = max(spec.species[k - 1].density for k in species)
    lightest = min(spec.species[k - 1].density for k in species) * smallest  # kg
    # the most particles the request can make (per second, by rate)
    count = {"particles_in_region": value, "particlerate": value}.get(target, value / lightest)
    if target == "volumefraction_region":
        count = value * region.volume() / smallest
    if target == "particles_in_region":
        check_packing(value, smallest, region, "insert", "particles", sizes, all_in)
    elif target == "mass_in_region":
        check_packing(value, 1 / density, region, "insert", "kg", sizes, all_in)
    duration = None if duration is None else positive_float(duration, "insert duration")
    if mechanism == "by_pack" or duration is not None:
        check_memory(count * (1 if duration is None else duration), "insert")
    freq = kwargs.get("freq", "once")
    orientation = kwargs.get("orientation", args.get("orientation"))
    return InsertSpec(
        mechanism=mechanism,
        target=target,
        value=value,
        species=species,
        weights=weights,
        region=region,
        velocity=parse_velocity(kwargs.get("vel_type", "constant"), kwargs.get("vel", (0, 0, 0))),
        omega=_omega(kwargs.get("omega", (0, 0, 0))),
        freq=None if isinstance(freq, str) and freq == "once" else step_count(freq, "insert freq", notes),
        duration=duration,
        all_in=all_in,
        seed=_seed(kwargs.get("seed", seed), "insert"),
        requested=value,
        orientation=None if orientation is None else parse_orientation(orientation, species, spec),
    )


def _region_in_box(value: Any, spec: SimulationSpec, call: str) -> Region:
    """The region of an ``insert`` or ``createParticles`` call, inside the box (see
    :func:`check_region_in_box`)."""
    region = parse_region(value, spec)
    check_region_in_box(region, spec, call)
    return region


def _omega(value: Any) -> Vector:
    """``(wx, wy, wz)`` or the manual's ``('constant', wx, wy, wz)``."""
    if isinstance(value, Sequence) and len(value) == 4 and value[0] == "constant":
        value = value[1:]
    return vector(value, "omega")


# -- create particles --------------------------------------------------------------------------


@dataclass(frozen=True)
class CreateSpec:
    """Particles of one species: ``single`` at ``position`` (or one at each row of the
    ``(N, 3)`` array ``positions``), a ``lattice`` of spacing ``spacing`` filling ``region``
    (its sites, from :func:`lattice_sites`, in ``positions``), or ``random``: ``count`` placed
    without overlap in ``region``."""

    species: int
    style: str
    position: Vector | None = None
    positions: np.ndarray | None = field(default=None, compare=False)
    region: Region | None = None
    spacing: float | None = None
    count: int | None = None
    velocity: Vector = (0.0, 0.0, 0.0)
    omega: Vector = (0.0, 0.0, 0.0)
    radius: float | None = None
    seed: int = 0

    @property
    def centres(self) -> np.ndarray:
        """The centres of the ``single`` and ``lattice`` styles as an ``(N, 3)`` array."""
        return self.positions if self.positions is not None else np.array([self.position], float)


def lattice_sites(region: Region, spacing: float, radius: float) -> np.ndarray:
    """The sites of a simple cubic lattice of ``spacing`` in ``region`` where a sphere of
    ``radius`` lies wholly inside it: from each lower bound plus half a spacing, ``(N, 3)``."""
    counts = [max(0.0, math.ceil((hi - lo - spacing / 2) / spacing)) for lo, hi in region.bounds()]
    check_memory(math.prod(counts), f"createParticles lattice of spacing {spacing:g}")
    axes = [np.arange(lo + spacing / 2, hi, spacing) for lo, hi in region.bounds()]
    sites = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return sites[region.contains(sites, radius)]


def sphere_rows(args: Sequence[Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """``(radii, positions)`` of ``createParticles(species, 'single', rows)`` when ``rows`` gives
    a radius per row: an ``(N, 4)`` array ``radius x y z`` or a table of
    :func:`~pygran_core.formats.tables.read_spheres`; ``None`` for other arguments."""
    if len(args) != 1:
        return None
    rows = args[0]
    if hasattr(rows, "radius") and hasattr(rows, "positions"):
        return np.asarray(rows.radius, float), np.asarray(rows.positions, float)
    if np.ndim(rows) == 2 and np.shape(rows)[1] == 4:
        table = np.asarray(rows, float)
        return table[:, 0], table[:, 1:]
    return None


def parse_create_rows(
    species: Any, args: Sequence[Any], kwargs: Mapping[str, Any], spec: SimulationSpec, seed: int
) -> list[CreateSpec]:
    """``createParticles(species, 'single', rows)`` with a radius per row (:func:`sphere_rows`):
    one request per species, each row going to the species (of ``species``: ``'all'``, a
    number or numbers) whose constant radius it has. A radius no species has, or two have, is
    a :class:`ConfigError`."""
    radii, positions = given(sphere_rows(args), "rows with radii")
    if "radius" in kwargs:
        raise ConfigError("createParticles: the rows give each particle's radius; drop radius=")
    if not np.isfinite(radii).all() or (radii <= 0).any():
        raise ConfigError("createParticles rows: every radius must be a finite number > 0")
    candidates = [spec.species[k - 1] for k in parse_species_selection(species, spec)]
    sizes = {s.type: s.radius.values[0] for s in candidates if s.radius.kind == "constant"}
    requests = []
    for radius in np.unique(radii):
        owners = [k for k, r in sizes.items() if math.isclose(r, radius, rel_tol=1e-9)]
        if len(owners) != 1:
            rows = np.flatnonzero(radii == radius)[:5].tolist()
            have = ", ".join(f"species {k}: {r:g} m" for k, r in sizes.items()) or "none of constant radius"
            whose = "no species"
            if owners:
                whose = f"species {' and '.join(map(str, owners))}: choose one with species="
            raise ConfigError(
                f"createParticles rows {rows}...: radius {radius:g} m is the radius of {whose} ({have}); "
                "give each radius a species of its own"
            )
        chosen = positions[radii == radius]
        requests.append(parse_create(owners[0], "single", (chosen,), kwargs, spec, seed))
    return requests


def parse_create(
    species: Any, style: Any, args: Sequence[Any], kwargs: Mapping[str, Any], spec: SimulationSpec, seed: int
) -> CreateSpec:
    check_keys("createParticles keyword", kwargs, ("vel", "omega", "radius", "region", "spacing", "seed"))
    (chosen,) = parse_species_selection(species, spec) if species != "all" else (None,)
    if chosen is None:
        raise ConfigError("createParticles needs one species number, not 'all'")
    style = one_of(style, "createParticles style", ("single", "lattice", "random"))
    common = {
        "species": chosen,
        "style": style,
        "velocity": vector(kwargs.get("vel", (0, 0, 0)), "vel"),
        "omega": _omega(kwargs.get("omega", (0, 0, 0))),
        "radius": None if kwargs.get("radius") is None else check_radius(kwargs["radius"], "radius"),
        "seed": _seed(kwargs.get("seed", seed), "createParticles"),
    }
    if style == "single":
        if len(args) == 1 and np.ndim(args[0]) == 2:
            positions = np.array(args[0], float)
            if positions.shape[1:] != (3,) or not len(positions) or not np.isfinite(positions).all():
                raise ConfigError(
                    "createParticles(species, 'single', positions): positions must be a non-empty "
                    f"(N, 3) array of finite coordinates, got shape {positions.shape}"
                )
            check_points_in_box(positions, spec, "createParticles position")
            positions.flags.writeable = False
            return CreateSpec(positions=positions, **common)
        if len(args) != 3:
            raise ConfigError(
                "createParticles(species, 'single', x, y, z) or (species, 'single', positions) with "
                f"an (N, 3) array: got {args!r}"
            )
        position = vector(args, "position")
        check_points_in_box(np.array([position]), spec, "createParticles position")
        return CreateSpec(position=position, **common)
    region = _region_in_box(kwargs.get("region"), spec, "createParticles")
    if style == "lattice":
        spacing = kwargs.get("spacing", args[0] if args else None)
        if spacing is None:
            raise ConfigError("createParticles(species, 'lattice', spacing, region=...): give the spacing")
        spacing = positive_float(spacing, "spacing")
        sizes = spec.species[chosen - 1].radius
        largest = common["radius"] or sizes.max
        if spacing < 2 * largest and not math.isclose(spacing, 2 * largest):
            raise ConfigError(
                f"createParticles lattice spacing {spacing:g} is below one diameter ({2 * largest:g}) of "
                f"the particles of species {chosen}: neighbours would overlap and fly apart. Give a "
                f"spacing of at least {2 * largest:g}"
            )
        sites = lattice_sites(region, spacing, common["radius"] or sizes.mean)
        if not len(sites):
            raise ConfigError(
                f"createParticles lattice: no site of spacing {spacing:g} in the region "
                f"{region} has room for a whole particle of species {chosen}; "
                "give a larger region or a smaller spacing"
            )
        sites.flags.writeable = False
        return CreateSpec(region=region, spacing=spacing, positions=sites, **common)
    if len(args) != 1:
        raise ConfigError("createParticles(species, 'random', count, region=...): give the count")
    count = positive_int(args[0], "count")
    extent = (common["radius"], common["radius"]) if common["radius"] else particle_sizes((chosen,), spec)
    volume = 4 / 3 * math.pi * extent[0] ** 3
    check_packing(count, volume, region, "createParticles", "particles", extent, all_in=True)
    check_memory(count, "createParticles")
    return CreateSpec(region=region, count=count, **common)


# -- walls, meshes -----------------------------------------------------------------------------


@dataclass(frozen=True)
class WallSpec:
    """A primitive wall (``plane`` x/y/z at ``peq``, or a ``cylinder`` of ``radius``
    about an axis) or a mesh wall made of the simulation's mesh ``mesh``; its material is
    that of species ``species`` (a mesh's own material when it has one)."""

    kind: str
    species: int
    plane: str | None = None
    peq: float | None = None
    axis: str | None = None
    centre: tuple[float, float] | None = None
    radius: float | None = None
    mesh: str | None = None


def check_plane_in_box(plane: str, peq: float, spec: SimulationSpec) -> None:
    """Refuse a plane wall outside the box, unless the face it lies beyond is shrink-wrapped:
    beyond a fixed face it holds nothing (the particles are lost before they reach it), beyond
    a periodic one no particle ever reaches it. A plane on a face of the box is a wall there."""
    axis = "xyz".index(plane[0])
    box, tol = _limits(spec)
    lo, hi = box[axis]
    side = 0 if peq < lo - tol else 1 if peq > hi + tol else None
    if side is None or _face_flag(spec, axis, side) in ("s", "m"):
        return
    raise ConfigError(
        f"setupWall(plane={plane!r}, peq={peq:g}): peq is outside the box, whose {plane[0]} runs from "
        f"{lo:g} to {hi:g}; particles never reach the wall. Give peq from {lo:g} to {hi:g} (a wall on a "
        "face of the box is at its bound)"
    )


def parse_wall(kwargs: Mapping[str, Any], spec: SimulationSpec) -> WallSpec:
    check_keys(
        "setupWall keyword", kwargs, ("wtype", "species", "plane", "peq", "axis", "centre", "radius", "mesh")
    )
    wtype = one_of(kwargs.get("wtype", "primitive"), "wtype", ("primitive", "mesh"))
    (species,) = parse_species_selection(kwargs.get("species", 1), spec)[:1]
    if wtype == "mesh":
        names = [m.name for m in spec.meshes]
        name = kwargs.get("mesh", names[0] if len(names) == 1 else None)
        if not isinstance(name, str) or name not in names:
            raise (
                unknown_key("mesh", str(name), names)
                if names
                else ConfigError(
                    "setupWall(wtype='mesh') needs a mesh: pass mesh={'name': {'file': ...}} to DEM"
                )
            )
        return WallSpec("mesh", species, mesh=name)
    plane = kwargs.get("plane")
    if plane is not None:
        if isinstance(plane, str):
            plane = {"planex": "xplane", "planey": "yplane", "planez": "zplane"}.get(plane, plane)
        plane = one_of(plane, "plane", ("xplane", "yplane", "zplane"))
        if kwargs.get("peq") is None:
            raise ConfigError(f"setupWall(plane={plane!r}) needs peq, the plane's coordinate")
        peq = finite_number(kwargs["peq"], "peq")
        check_plane_in_box(plane, peq, spec)
        return WallSpec("plane", species, plane=plane, peq=peq)
    if kwargs.get("radius") is not None:
        axis = one_of(kwargs.get("axis", "z"), "cylinder axis", ("x", "y", "z"))
        c1, c2 = number_tuple(kwargs.get("centre", (0, 0)), "centre", 2)
        return WallSpec(
            "cylinder", species, axis=axis, centre=(c1, c2), radius=positive_float(kwargs["radius"], "radius")
        )
    raise ConfigError("setupWall(wtype='primitive') needs plane='zplane' and peq=..., or axis/centre/radius")


@dataclass(frozen=True)
class MotionSpec:
    """Rigid motion of a mesh, as LIGGGHTS' ``fix move/mesh`` styles, time ``t`` counted
    from the ``moveMesh`` call:

    - ``rotate`` about ``axis`` through ``origin`` at ``omega`` rad/s (right-handed);
    - ``linear`` at ``velocity``;
    - ``wiggle``: displacement ``amplitude * sin(2 pi t / period)`` (``amplitude`` a vector);
    - ``viblin``: along the unit ``axis`` at the velocity
      ``-sum_i amplitudes[i] * w_i * sin(w_i t + phases[i])``, ``w_i = 2 pi / periods[i]``;
    - ``vibrot``: about ``axis`` through ``origin`` at that angular velocity (amplitudes in rad).
    """

    mesh: str
    kind: str
    axis: Vector | None = None
    origin: Vector = (0.0, 0.0, 0.0)
    omega: float | None = None
    velocity: Vector | None = None
    amplitude: Vector | None = None
    period: float | None = None
    amplitudes: tuple[float, ...] = ()
    phases: tuple[float, ...] = ()
    periods: tuple[float, ...] = ()


MOTION_STYLES = ("rotate", "linear", "wiggle", "viblin", "vibrot")
#: The arguments of each style (``moveMesh`` keywords, or words inside the style's tuple).
MOTION_ARGUMENTS = {
    "rotate": ("origin", "axis", "period", "omega"),
    "linear": (),
    "wiggle": ("amplitude", "period"),
    "viblin": ("axis", "order", "amplitude", "phase", "period"),
    "vibrot": ("origin", "axis", "order", "amplitude", "phase", "period"),
}
FORMS = (
    "rotate=('origin', x, y, z), axis=(ax, ay, az), period=s (or rotate=True, origin=..., omega=rad/s); "
    "linear=(vx, vy, vz); wiggle=('amplitude', ax, ay, az), period=s; "
    "viblin=('axis', ax, ay, az), order=n, amplitude=..., phase=..., period=...; "
    "vibrot=('origin', x, y, z), axis=..., order=n, amplitude=..., phase=..., period=..."
)


def _motion_words(style: str, value: Any) -> dict[str, list[Any]]:
    """The keyword/values pairs inside a style's value: ``('origin', 0, 0, 0)`` or LIGGGHTS
    words such as ``'origin 0 0 0 axis 0 0 1 period 0.1'``; ``True`` holds none."""
    if value is True:
        return {}
    items = value.split() if isinstance(value, str) else value
    if not isinstance(items, Sequence) or not items or not isinstance(items[0], str) or _is_number(items[0]):
        raise ConfigError(f"moveMesh {style}={value!r}: expected the forms {FORMS}")
    words: dict[str, list[Any]] = {}
    key = ""
    for item in items:
        if isinstance(item, str) and not _is_number(item):
            key = item
            if key in words:
                raise ConfigError(f"moveMesh {style}: {key!r} is given twice in {value!r}")
            words[key] = []
        elif is_real(item) or isinstance(item, str):
            words[key].append(float(item))
        else:
            raise ConfigError(f"moveMesh {style}: {item!r} in {value!r} is neither a keyword nor a number")
    return words


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def positional_motion(args: Sequence[Any]) -> dict[str, Any]:
    """PyGran 1.x's ``moveMesh(name, *args)``: LIGGGHTS' ``move/mesh`` words after the mesh,
    style first (``('viblin', 'axis 0 0 1', 'order 1', ...)``, ``('linear', 0, 0, -1)``), as
    the keyword form :func:`parse_motion` reads."""
    words = " ".join(str(a) for a in args).split()
    if not words or words[0] not in MOTION_STYLES:
        raise ConfigError(
            f"moveMesh(name, *args) takes LIGGGHTS' move/mesh words, a style ({', '.join(MOTION_STYLES)}) "
            f"first, e.g. ('rotate', 'origin 0 0 0', 'axis 0 0 1', 'period 0.1'); got {tuple(args)!r}. "
            f"The keyword forms: {FORMS}"
        )
    style, rest = words[0], words[1:]
    if style == "linear":
        if len(rest) != 3 or not all(_is_number(w) for w in rest):
            raise ConfigError(f"moveMesh(name, 'linear', vx, vy, vz) needs 3 numbers, got {tuple(args)!r}")
        return {"linear": tuple(float(w) for w in rest)}
    return {style: " ".join(rest) if rest else True}


#: The fastest a mesh may move (m/s): faster than sound in any solid, a mistake in units.
MAX_MESH_SPEED = 1e4


def peak_speed(motion: MotionSpec, spec: SimulationSpec) -> float:
    """The largest speed (m/s) a point of the mesh reaches in ``motion``."""
    if motion.kind == "linear":
        return float(np.linalg.norm(given(motion.velocity, "a linear motion's velocity")))
    if motion.kind == "wiggle":
        amplitude = float(np.linalg.norm(given(motion.amplitude, "a wiggle's amplitude")))
        return 2 * math.pi * amplitude / given(motion.period, "a wiggle's period")
    if motion.kind == "rotate":
        angular = abs(given(motion.omega, "a rotation's omega"))
    else:
        angular = sum(2 * math.pi * abs(a) / t for a, t in zip(motion.amplitudes, motion.periods))
        if motion.kind == "viblin":
            return angular
    (mesh,) = [m for m in spec.meshes if m.name == motion.mesh]
    points = mesh.triangles().reshape(-1, 3) - np.asarray(motion.origin)
    axis = np.asarray(given(motion.axis, "the motion's axis"))
    reach = float(np.max(np.linalg.norm(points - np.outer(points @ axis, axis), axis=1)))
    return angular * reach


def check_mesh_speed(motion: MotionSpec, spec: SimulationSpec) -> None:
    """Refuse a motion faster than :data:`MAX_MESH_SPEED`, or, when the time step is known,
    one that moves the mesh more than half the neighbour skin per step (the limit of
    LIGGGHTS' servo walls: contacts with it would be missed)."""
    speed = peak_speed(motion, spec)
    limits = [(MAX_MESH_SPEED, "faster than sound in any solid: check the units")]
    if spec.dt is not None and spec.skin > 0:
        limits.append((spec.skin / (2 * spec.dt), "skin / (2 dt): half the neighbour skin per step"))
    for limit, why in limits:
        if not speed <= limit:
            raise ConfigError(
                f"moveMesh {motion.mesh!r} {motion.kind}: the mesh reaches {speed:.3g} m/s, above "
                f"{limit:.3g} m/s ({why}); move it more slowly"
            )


def parse_motion(mesh: Any, kwargs: Mapping[str, Any], spec: SimulationSpec) -> MotionSpec:
    """``moveMesh(name, ...)`` in LIGGGHTS' ``move/mesh`` terms (see :class:`MotionSpec`),
    no faster than :func:`check_mesh_speed` allows."""
    motion = _parse_motion(mesh, kwargs, spec)
    check_mesh_speed(motion, spec)
    return motion


def _parse_motion(mesh: Any, kwargs: Mapping[str, Any], spec: SimulationSpec) -> MotionSpec:
    """The style's keyword holds the style's first arguments (PyGran 1.x's
    ``rotate=('origin', 0, 0, 0)``), the others follow as keywords (``axis=``, ``period=``)."""
    names = [m.name for m in spec.meshes]
    drum = (
        "a rotating drum is a mesh: mesh={'drum': {'triangles': simulation.geometry.drum(radius=..., "
        "length=..., axis='y'), 'material': ...}}, then moveMesh('drum', rotate=...)"
    )
    if getattr(mesh, "kind", None) == "wall":  # a primitive wall's handle
        raise ConfigError(
            f"moveMesh moves mesh walls, and {mesh} is a primitive wall: primitive planes and cylinders "
            f"are fixed, infinite surfaces on every engine (LIGGGHTS' primitives do not move); {drum}"
        )
    if not isinstance(mesh, str) or mesh not in names:
        if not names:
            raise ConfigError(f"moveMesh({mesh!r}): this simulation has no mesh to move; {drum}")
        raise unknown_key("mesh", str(mesh), names)
    check_keys(
        "moveMesh keyword",
        kwargs,
        MOTION_STYLES + ("origin", "axis", "period", "omega", "amplitude", "order", "phase"),
    )
    kinds = [k for k in MOTION_STYLES if k in kwargs and kwargs[k] is not False and kwargs[k] is not None]
    if len(kinds) != 1:
        raise ConfigError(f"moveMesh needs exactly one motion style: {FORMS}")
    kind = kinds[0]
    if kind == "linear":
        extra = [k for k in kwargs if k != "linear"]
        if extra:
            raise ConfigError(f"moveMesh(linear=(vx, vy, vz)) takes no {extra[0]!r}")
        return MotionSpec(mesh, kind, velocity=vector(kwargs["linear"], "moveMesh linear velocity"))
    given: dict[str, Any] = _motion_words(kind, kwargs[kind])
    for key, value in kwargs.items():
        if key == kind:
            continue
        if key in given:
            raise ConfigError(f"moveMesh {kind}: {key!r} is given twice, inside {kind}= and as a keyword")
        given[key] = value
    allowed = MOTION_ARGUMENTS[kind]
    for key in given:
        if key not in allowed:
            raise ConfigError(
                f"moveMesh {kind} takes {', '.join(allowed)}, not {key!r}. The forms: {FORMS}"
                + did_you_mean(key, allowed)
            )

    def motion_vector(key: str, default: Any = None) -> Vector:
        value = given.get(key, default)
        if value is None:
            raise ConfigError(f"moveMesh {kind} needs {key}=(x, y, z). The forms: {FORMS}")
        return vector(value, f"moveMesh {kind} {key}")

    def direction(key: str, default: Any = None) -> Vector:
        axis = np.array(motion_vector(key, default))
        if not np.linalg.norm(axis) > 0:
            raise ConfigError(f"moveMesh {kind} {key} must not be zero")
        return vector((axis / np.linalg.norm(axis)).tolist(), f"moveMesh {kind} {key}")

    def scalar(key: str) -> Any:
        value = given.get(key)
        if isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 1:
            value = value[0]
        return value

    if kind == "wiggle":
        return MotionSpec(
            mesh,
            kind,
            amplitude=motion_vector("amplitude"),
            period=positive_float(scalar("period"), "moveMesh wiggle period"),
        )
    if kind == "rotate":
        if ("period" in given) == ("omega" in given):
            raise ConfigError("moveMesh rotate needs either period= (s) or omega= (rad/s)")
        omega = (
            2 * math.pi / positive_float(scalar("period"), "moveMesh rotate period")
            if "period" in given
            else finite_number(scalar("omega"), "moveMesh rotate omega")
        )
        origin = motion_vector("origin", (0, 0, 0))
        axis = direction("axis")  # LIGGGHTS' rotate has no default axis either
        return MotionSpec(mesh, kind, axis=axis, origin=origin, omega=omega)
    order = scalar("order")
    if not is_real(order) or order not in range(1, 31):
        raise ConfigError(f"moveMesh {kind} needs order=n, the number of harmonics (1 to 30), got {order!r}")
    order = int(order)

    def harmonics(key: str, positive: bool = False) -> tuple[float, ...]:
        value = given.get(key)
        values = [value] if isinstance(value, Real) else value
        if key == "period" and isinstance(values, Sequence) and len(values) == 1:
            values = list(values) * order  # one period for every harmonic
        if isinstance(values, str) or not isinstance(values, Sequence) or len(values) != order:
            raise ConfigError(
                f"moveMesh {kind} needs {key}= with {order} value(s) (order={order}), got {value!r}"
            )
        check = positive_float if positive else finite_number
        return tuple(check(v, f"moveMesh {kind} {key}") for v in values)

    return MotionSpec(
        mesh,
        kind,
        axis=direction("axis"),
        origin=motion_vector("origin", (0, 0, 0)) if kind == "vibrot" else (0.0, 0.0, 0.0),
        amplitudes=harmonics("amplitude"),
        phases=harmonics("phase"),
        periods=harmonics("period", positive=True),
    )


# -- forces, monitors ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ViscousSpec:
    """A drag force ``F = -gamma * scale * v`` on particles of ``species``."""

    gamma: float
    species: tuple[int, ...]
    scale: float = 1.0


def parse_viscous(kwargs: Mapping[str, Any], spec: SimulationSpec) -> ViscousSpec:
    check_keys("addViscous keyword", kwargs, ("gamma", "species", "scale"))
    if "gamma" not in kwargs:
        raise ConfigError("addViscous needs gamma, the drag coefficient (kg/s)")
    return ViscousSpec(
        positive_float(kwargs["gamma"], "gamma"),
        parse_species_selection(kwargs.get("species", "all"), spec),
        positive_float(kwargs.get("scale", 1.0), "scale"),
    )


MONITOR_QUANTITIES = ("ke", "ke_rot", "n", "contacts", "time", "wall_force")


@dataclass(frozen=True)
class MonitorSpec:
    """Scalars sampled every ``freq`` steps, kept in memory and written to ``file``; of the
    particles of ``species`` only (``None``: of every particle)."""

    quantities: tuple[str, ...]
    freq: int
    file: str
    species: tuple[int, ...] | None = None


def parse_monitor(kwargs: Mapping[str, Any], notes: list[str] | None = None) -> MonitorSpec:
    check_keys("monitor keyword", kwargs, ("quantities", "freq", "file", "name"))
    quantities = kwargs.get("quantities", ("ke",))
    quantities = (quantities,) if isinstance(quantities, str) else quantities
    if not isinstance(quantities, Sequence):
        raise ConfigError(f"monitor quantities must be names such as ('ke', 'n'), got {quantities!r}")
    for quantity in quantities:
        one_of(quantity, "monitor quantity", MONITOR_QUANTITIES)
    return MonitorSpec(
        tuple(quantities),
        step_count(kwargs.get("freq", 100), "monitor freq", notes),
        str(kwargs.get("file", f"{kwargs.get('name', 'monitor')}.txt")),
    )


#: PyGran 1.x's monitor ``var`` (a LIGGGHTS compute style) and the quantity it samples.
AVERAGE_VARS = {"ke": "ke", "erotate/sphere": "ke_rot", "erotate": "ke_rot"}
#: The keywords of PyGran 1.x's monitor, LIGGGHTS' ``compute`` + ``fix ave/time``.
AVERAGE_KEYS = ("var", "species", "name", "file", "nevery", "nrepeat", "nfreq")


@dataclass(frozen=True)
class AverageSpec:
    """PyGran 1.x's ``monitor(var='ke', species='all', name=..., file=..., nevery=,
    nrepeat=, nfreq=)``: LIGGGHTS' ``compute <var>`` of the species' particles averaged as
    ``fix ave/time nevery nrepeat nfreq``: on every step that is a multiple of ``nfreq``,
    the mean of the ``nrepeat`` values sampled every ``nevery`` steps up to it, written to
    ``file`` as LIGGGHTS does (``step value`` lines after two ``#`` lines)."""

    quantity: str
    var: str
    species: tuple[int, ...]
    name: str
    file: str
    nevery: int = 1
    nrepeat: int = 1
    nfreq: int = 1

    def samples(self, every_species: bool = True) -> MonitorSpec:
        """The engine monitor this average reads: the quantity every ``nevery`` steps, of the
        chosen species (of every particle when they are all the simulation's species)."""
        species = None if every_species else self.species
        return MonitorSpec((self.quantity,), self.nevery, f"{self.name}-samples.txt", species)

    def average(self, steps: np.ndarray, values: np.ndarray, since: int) -> tuple[np.ndarray, np.ndarray]:
        """The averages (steps, means) of the samples ``values`` taken at ``steps``, for the
        output steps at or after ``since`` (the step the monitor began) whose samples are all there."""
        sampled = dict(zip(steps.astype(np.int64).tolist(), values.tolist()))
        span = (self.nrepeat - 1) * self.nevery
        first = -(-(since + span) // self.nfreq) * self.nfreq
        out_steps, means = [], []
        for step in range(first, int(steps.max(initial=-1)) + 1, self.nfreq):
            window = range(step - span, step + 1, self.nevery)
            if all(s in sampled for s in window):
                out_steps.append(step)
                means.append(float(np.mean([sampled[s] for s in window])))
        return np.array(out_steps, np.int64), np.array(means, float)


def parse_average(
    kwargs: Mapping[str, Any], spec: SimulationSpec, notes: list[str] | None = None
) -> AverageSpec:
    """PyGran 1.x's monitor keywords (:data:`AVERAGE_KEYS`, its defaults ``nevery = nrepeat
    = nfreq = 1``), checked as LIGGGHTS checks ``fix ave/time``."""
    check_keys("monitor keyword", kwargs, AVERAGE_KEYS)
    if "var" not in kwargs:
        raise ConfigError(f"monitor(var=..., ...) needs var, one of {', '.join(AVERAGE_VARS)}")
    var = kwargs["var"]
    quantity = AVERAGE_VARS[one_of(var, "monitor var", list(AVERAGE_VARS))]
    counts = {
        key: step_count(kwargs.get(key, 1), f"monitor {key}", notes) for key in ("nevery", "nrepeat", "nfreq")
    }
    if counts["nfreq"] % counts["nevery"] or counts["nrepeat"] * counts["nevery"] > counts["nfreq"]:
        raise ConfigError(
            f"monitor nevery={counts['nevery']}, nrepeat={counts['nrepeat']}, nfreq={counts['nfreq']}: "
            "nfreq must be a multiple of nevery and nrepeat * nevery at most nfreq (LIGGGHTS' fix ave/time)"
        )
    name = kwargs.get("name", str(var).replace("/", "_"))
    if not isinstance(name, str) or not name or any(c in name for c in "/\\ "):
        raise ConfigError(f"monitor name must be a word such as 'ensemble_ke', got {name!r}")
    file = kwargs.get("file", f"{name}.dat")
    if not isinstance(file, str) or not file:
        raise ConfigError(f"monitor file must be a file name such as 'ke.dat', got {file!r}")
    return AverageSpec(
        quantity=quantity,
        var=var,
        species=parse_species_selection(kwargs.get("species", "all"), spec),
        name=name,
        file=file,
        **counts,
    )


# -- assigning properties ----------------------------------------------------------------------


@dataclass(frozen=True)
class SetSpec:
    """New ``velocity``, ``omega`` and/or ``radius`` for the particles of ``species``, inside
    ``region`` and/or with the given ``ids`` (all conditions that are given must hold)."""

    species: tuple[int, ...] | None = None
    region: Region | None = None
    ids: tuple[int, ...] | None = None
    velocity: Vector | None = None
    omega: Vector | None = None
    radius: float | None = None

    def select(self, ids: np.ndarray, types: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """The ids (of ``ids``, with ``types`` and ``positions`` alike) this request applies to."""
        chosen = np.ones(len(ids), bool)
        if self.species is not None:
            chosen &= np.isin(types, self.species)
        if self.region is not None:
            chosen &= self.region.contains(positions)
        if self.ids is not None:
            chosen &= np.isin(ids, self.ids)
        return ids[chosen]


def parse_set(kwargs: Mapping[str, Any], spec: SimulationSpec) -> SetSpec:
    check_keys("set keyword", kwargs, ("species", "region", "ids", "vel", "omega", "radius"))
    velocity = None if kwargs.get("vel") is None else vector(kwargs["vel"], "vel")
    omega = None if kwargs.get("omega") is None else _omega(kwargs["omega"])
    radius = None if kwargs.get("radius") is None else positive_float(kwargs["radius"], "radius")
    if velocity is None and omega is None and radius is None:
        raise ConfigError(
            "set/velocity needs something to assign: vel=(vx, vy, vz), omega=(...) or radius=..."
        )
    ids = kwargs.get("ids")
    if ids is not None:
        ids = (ids,) if isinstance(ids, Integral) else ids
        if (
            isinstance(ids, str)
            or not isinstance(ids, Sequence)
            or not ids
            or any(not is_integer(i) or i < 1 for i in ids)
        ):
            raise ConfigError(f"ids must be particle ids (1, 2, ...), got {kwargs['ids']!r}")
    return SetSpec(
        species=None if kwargs.get("species") is None else parse_species_selection(kwargs["species"], spec),
        region=None if kwargs.get("region") is None else parse_region(kwargs["region"], spec),
        ids=None if ids is None else tuple(int(i) for i in ids),
        velocity=velocity,
        omega=omega,
        radius=radius,
    )
