"""Engine-neutral specifications: what a user asked for, validated once, in SI units.

:func:`parse_simulation` turns the keywords of ``simulation.DEM(**params)`` (manual,
chapter 4) into a :class:`SimulationSpec`; the ``parse_*`` functions below do the same for
each call (``insert``, ``setupWall``, ...). Engines receive only these frozen records, so
each engine maps one well-defined request onto its solver and never re-validates input.
Unknown keywords are a :class:`~pygran_core.errors.ConfigError` that names the closest
known one; numbers may be ints or floats everywhere.
"""

from __future__ import annotations

import inspect
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from numbers import Integral, Real
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from pygran_core import params as materials
from pygran_core.errors import ConfigError, ReadError, UnsupportedFeature, unknown_key
from pygran_core.formats.stl import STLTrajectory
from pygran_core.formats.tables import read_triangles
from pygran_core.simulation import geometry
from pygran_core.simulation.materials import Pairs, parse_pairs
from pygran_core.simulation.models.base import ContactModel
from pygran_core.simulation.mpi import rank0_value

Vector = tuple[float, float, float]
BOUNDARY_FLAGS = frozenset("pfsm")


# -- small validators --------------------------------------------------------------------


T = TypeVar("T")


def given(value: T | None, what: str) -> T:
    """``value``, which ``what`` needs: the front end's parsing sets it for that kind of call
    (a wall's plane, an insertion's count), a spec made by hand may lack it."""
    if value is None:
        raise ConfigError(f"{what} is not given")
    return value


def optional_bool(value: Any, name: str, allow_none: bool = True) -> bool | None:
    """``value`` as True, False or (with ``allow_none``, meaning automatic) None, or a
    :class:`ConfigError` naming ``name``: a string such as ``'no'`` is refused, not read as true."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if value is None and allow_none:
        return None
    raise ConfigError(f"{name} must be True{', False or None' if allow_none else ' or False'}, got {value!r}")


def is_real(value: Any) -> bool:
    """``value`` is a real number (numpy's too), not a bool."""
    return isinstance(value, Real) and not isinstance(value, bool)


def is_integer(value: Any) -> bool:
    """``value`` is an integer (numpy's too), not a bool."""
    return isinstance(value, Integral) and not isinstance(value, bool)


def positive_int(value: Any, name: str) -> int:
    """``value`` as an int > 0, or a :class:`ConfigError` naming ``name``."""
    if not is_integer(value) or value <= 0:
        raise ConfigError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def step_count(value: Any, name: str, notes: list[str] | None = None) -> int:
    """A number of steps (or a frequency in steps) as LIGGGHTS reads one: an int, or a float
    truncated toward zero (``1e5`` is 100000 steps, ``1e5 / 3`` is 33333). When truncation
    changes the value, a line saying so is appended to ``notes`` (for ``pygran.log``)."""
    if not is_real(value) or not math.isfinite(value):
        raise ConfigError(f"{name} must be a number of steps such as 1000 or 1e5, got {value!r}")
    steps = int(value)
    if steps <= 0:
        raise ConfigError(f"{name} must be at least 1 step, got {value!r}")
    if steps != value and notes is not None:
        notes.append(f"{name} {value!r} truncated to {steps} steps")
    return steps


def positive_float(value: Any, name: str) -> float:
    """``value`` (int or float) as a finite float > 0, or a :class:`ConfigError` naming ``name``."""
    if not is_real(value) or not 0 < value < math.inf:
        raise ConfigError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def finite_number(value: Any, name: str) -> float:
    if not is_real(value) or not math.isfinite(value):
        raise ConfigError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def number_tuple(value: Any, name: str, size: int = 3) -> tuple[float, ...]:
    """``size`` finite numbers from a sequence or a one-dimensional numpy array."""
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != size:
        raise ConfigError(f"{name} must be a sequence of {size} numbers, got {value!r}")
    return tuple(finite_number(v, f"{name}[{i}]") for i, v in enumerate(value))


def vector(value: Any, name: str) -> Vector:
    """Three finite numbers ``(x, y, z)``, or a :class:`ConfigError` naming ``name``."""
    x, y, z = number_tuple(value, name)
    return (x, y, z)


def one_of(value: Any, name: str, choices: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise unknown_key(f"{name}", str(value), choices)
    return value


#: Characters a solver's input language gives a meaning of its own: LIGGGHTS reads ``#`` as
#: the start of a comment, ``$`` as a variable, quotes as the ends of a word and a final ``&``
#: as a continued line. A word holding one is refused, never passed on.
COMMAND_CHARACTERS = frozenset("#$'\"&")


def control_characters(text: str) -> list[str]:
    """The control characters (line breaks, tabs, NUL, ...) in ``text``, each as its ``repr``."""
    return sorted({repr(c) for c in text if ord(c) < 32 or 127 <= ord(c) < 160})


def command_words(words: Sequence[str], name: str) -> tuple[str, ...]:
    """``words`` as a solver's input may carry them, or a :class:`ConfigError` naming
    ``name`` and the character: a control character would start a new command line, and
    :data:`COMMAND_CHARACTERS` would drop or change the rest of the line."""
    for word in words:
        bad = control_characters(word) + sorted(repr(c) for c in COMMAND_CHARACTERS & set(word))
        if bad:
            raise ConfigError(
                f"{name}: {word!r} holds {', '.join(bad)}, which a solver's input reads as the end of "
                "the line, a comment, a variable, a quote or a continuation: give plain words such as "
                "('sort id',)"
            )
    return tuple(words)


def words(value: Any, name: str) -> tuple[str, ...]:
    """``value`` as a tuple of plain words (one string is one word), see :func:`command_words`."""
    value = (value,) if isinstance(value, str) else value
    if not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{name} must be a sequence of words such as ('id', 'x'), got {value!r}")
    return command_words(value, name)


def columns(value: Any, name: str) -> tuple[str, ...]:
    """Column names as a sequence, or as LIGGGHTS' ``dump custom`` takes them: one string of
    names separated by spaces (``'id type x y z'``)."""
    return words(value.split() if isinstance(value, str) else value, name)


def file_name(value: Any, name: str) -> str | os.PathLike[str]:
    """A file or folder name without control characters (a line break or NUL in a name
    breaks every tool that lists or reads it back), or a :class:`ConfigError` naming ``name``."""
    if not isinstance(value, (str, os.PathLike)) or not isinstance(os.fspath(value), str) or not str(value):
        raise ConfigError(f"{name} must be a file or folder name, got {value!r}")
    bad = control_characters(str(value))
    if bad:
        raise ConfigError(f"{name} {str(value)!r} holds the control character(s) {', '.join(bad)}: rename it")
    return value


def command_path(path: Path, name: str, patterns: bool = False, folder: bool = False) -> Path:
    """``path`` as LIGGGHTS' input can name it, so that the saved input reruns as the live
    run ran, or a :class:`ConfigError` naming ``name``: no ``$`` (a variable, even in
    quotes), not both kinds of quote (no quoting could hold it); with ``patterns`` (a file
    LIGGGHTS names by step or processor: dumps, restarts; or a ``folder`` holding them) ``*``
    and ``%`` only in the file name itself, where they mean the step and the processor."""
    text = str(path)
    file_name(text, name)
    fault = None
    if "$" in text:
        fault = "'$', which LIGGGHTS reads as a variable even inside quotes"
    elif "'" in text and '"' in text:
        fault = "both kinds of quote, which no LIGGGHTS word can hold"
    elif patterns and any(c in str(path if folder else path.parent) for c in "*%"):
        fault = "'*' or '%' in a folder name, which LIGGGHTS reads as the step or the processor"
    if fault is not None:
        raise ConfigError(f"{name} {text!r} holds {fault}: choose a name without it for the LIGGGHTS engine")
    return path


def check_keys(kind: str, given: Mapping[str, Any], known: Sequence[str]) -> None:
    for key in given:
        if key not in known:
            raise unknown_key(kind, str(key), known)


def edits(a: str, b: str) -> int:
    """The number of single-letter insertions, deletions, substitutions and swaps of two
    neighbours that turn ``a`` into ``b`` (optimal string alignment distance)."""
    previous: list[int] = []
    current = list(range(len(b) + 1))
    for i, x in enumerate(a, start=1):
        before, previous, current = previous, current, [i] + [0] * len(b)
        for j, y in enumerate(b, start=1):
            current[j] = min(previous[j] + 1, current[j - 1] + 1, previous[j - 1] + (x != y))
            if i > 1 and j > 1 and x == b[j - 2] and a[i - 2] == y:
                current[j] = min(current[j], before[j - 2] + 1)
    return current[-1]


def near_miss(key: str, known: Sequence[str]) -> str | None:
    """The known keyword ``key`` is probably a misspelling of: within two edits of it (one
    where either word has at most three letters), else ``None``."""
    best = min(known, key=lambda k: edits(key, k))
    allowed = 1 if min(len(key), len(best)) <= 3 else 2
    return best if edits(key, best) <= allowed else None


# -- domain, gravity -----------------------------------------------------------------------


@dataclass(frozen=True)
class Domain:
    """The simulation box ``((xlo, xhi), (ylo, yhi), (zlo, zhi))`` and its boundary flags.

    Each flag is one letter for both faces (``"p"`` periodic, ``"f"`` fixed, ``"s"``
    shrink-wrapped, ``"m"`` shrink-wrapped with a minimum) or two letters, lower then upper
    face (``"fs"``); periodic faces come in pairs.
    """

    box: tuple[tuple[float, float], ...]
    boundary: tuple[str, str, str] = ("f", "f", "f")

    @property
    def periodic(self) -> tuple[bool, bool, bool]:
        x, y, z = (flag == "p" for flag in self.boundary)
        return (x, y, z)

    @property
    def lengths(self) -> np.ndarray:
        return np.array([hi - lo for lo, hi in self.box])


def parse_box(value: Any) -> tuple[tuple[float, float], ...]:
    numbers = number_tuple(value, "box", 6)
    box = tuple((numbers[2 * i], numbers[2 * i + 1]) for i in range(3))
    for axis, (lo, hi) in zip("xyz", box):
        if not lo < hi:
            raise ConfigError(f"box: {axis} lower bound {lo} must be below the upper bound {hi}")
    return box


def parse_boundary(value: Any) -> tuple[str, str, str]:
    if isinstance(value, str) or not isinstance(value, Sequence) or len(value) != 3:
        raise ConfigError(f"boundary must be three flags such as ('p', 'p', 'f'), got {value!r}")
    flags = []
    for axis, flag in zip("xyz", value):
        if not isinstance(flag, str) or not 1 <= len(flag) <= 2 or set(flag) - BOUNDARY_FLAGS:
            raise ConfigError(
                f"boundary {axis}: {flag!r} is not a flag; use one or two of p, f, s, m (e.g. 'f', 'fs')"
            )
        if "p" in flag and flag not in ("p", "pp"):
            raise ConfigError(f"boundary {axis}: {flag!r} mixes periodic and non-periodic faces")
        flags.append("p" if flag == "pp" else flag if len(flag) == 1 or flag[0] != flag[1] else flag[0])
    return (flags[0], flags[1], flags[2])


@dataclass(frozen=True)
class Gravity:
    """Gravitational acceleration ``magnitude`` (m/s^2) along the unit vector ``direction``."""

    magnitude: float
    direction: Vector

    @property
    def vector(self) -> np.ndarray:
        return self.magnitude * np.asarray(self.direction)


def parse_gravity(value: Any) -> Gravity:
    """Gravity as ``(g, dx, dy, dz)`` (published scripts) or ``(dx, dy, dz, g)`` (manual).

    The form is recognised by which triple is a unit vector; a tuple where both or neither
    triple is a unit vector is ambiguous or wrong and is rejected.
    """
    numbers = number_tuple(value, "gravity", 4)
    first, last = np.array(numbers[1:]), np.array(numbers[:3])
    first_unit = math.isclose(float(np.linalg.norm(first)), 1.0, rel_tol=1e-6)
    last_unit = math.isclose(float(np.linalg.norm(last)), 1.0, rel_tol=1e-6)
    if first_unit == last_unit:
        raise ConfigError(
            f"gravity {tuple(numbers)} is ambiguous or invalid: give (magnitude, dx, dy, dz) or "
            "(dx, dy, dz, magnitude) with (dx, dy, dz) a unit vector, e.g. (9.81, 0, 0, -1)"
        )
    magnitude, direction = (numbers[0], numbers[1:]) if first_unit else (numbers[3], numbers[:3])
    if magnitude < 0:
        raise ConfigError(f"gravity magnitude must be >= 0, got {magnitude}")
    return Gravity(magnitude, vector(direction, "gravity direction"))


# -- particle sizes, species ---------------------------------------------------------------


@dataclass(frozen=True)
class RadiusDistribution:
    """A particle size distribution.

    ``("constant", r)``; ``("normal", mean, std)`` and ``("lognormal", median, sigma)``
    (sigma of ln r), both truncated to 3 standard deviations so the largest radius is
    known in advance; ``("poly", (r1, r2, ...), (w1, w2, ...))`` with number fractions.
    """

    kind: str
    values: tuple[float, ...]
    weights: tuple[float, ...] = ()

    @property
    def max(self) -> float:
        if self.kind == "constant":
            return self.values[0]
        if self.kind == "normal":
            return self.values[0] + 3 * self.values[1]
        if self.kind == "lognormal":
            return self.values[0] * math.exp(3 * self.values[1])
        return max(self.values)

    @property
    def min(self) -> float:
        if self.kind == "constant":
            return self.values[0]
        if self.kind == "normal":
            return self.values[0] - 3 * self.values[1]
        if self.kind == "lognormal":
            return self.values[0] * math.exp(-3 * self.values[1])
        return min(self.values)

    @property
    def mean(self) -> float:
        if self.kind in ("constant", "normal"):
            return self.values[0]
        if self.kind == "lognormal":
            return self.values[0] * math.exp(self.values[1] ** 2 / 2)
        return float(np.dot(self.values, self.weights))

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` radii drawn with ``rng``."""
        if self.kind == "constant":
            return np.full(count, self.values[0])
        if self.kind == "poly":
            return rng.choice(np.array(self.values), size=count, p=np.array(self.weights))
        location, spread = self.values
        normal = rng.standard_normal(count)
        while np.any(bad := np.abs(normal) > 3):
            normal[bad] = rng.standard_normal(int(bad.sum()))
        return location + spread * normal if self.kind == "normal" else location * np.exp(spread * normal)


#: The radii (m) a particle may have: below a nanometre a particle is a handful of atoms, which
#: DEM's contact laws do not describe (and whose mass underflows); above a kilometre, a
#: mistake in units.
RADIUS_RANGE = (1e-9, 1e3)


def check_radius(value: Any, name: str) -> float:
    """``value``, a positive radius within :data:`RADIUS_RANGE`, or a :class:`ConfigError`."""
    lo, hi = RADIUS_RANGE
    if not lo <= positive_float(value, name) <= hi:
        raise ConfigError(f"{name} {value:g} m is outside the radii DEM describes, {lo:g} to {hi:g} m")
    return float(value)


def check_span(value: Any, smallest: float, largest: float, text: tuple[str, str] | None = None) -> None:
    """Refuse a radius distribution ``value`` whose radii reach outside :data:`RADIUS_RANGE`;
    ``text`` writes the two radii where a float cannot hold them."""
    lo, hi = RADIUS_RANGE
    if smallest == largest:
        check_radius(smallest, f"radius {value!r}:")
    if not lo <= smallest <= largest <= hi:
        low, high = text or (f"{smallest:.3g}", f"{largest:.3g}")
        raise ConfigError(
            f"radius {value!r} spans radii from {low} to {high} m (a normal or lognormal distribution is "
            f"cut at 3 sigma), but radii must lie between {lo:g} and {hi:g} m"
        )


def parse_radius(value: Any) -> RadiusDistribution:
    if is_real(value):
        value = ("constant", value)
    if isinstance(value, str) or not isinstance(value, Sequence) or not value:
        raise ConfigError(
            f"radius must be a number or a distribution such as ('normal', 1e-4, 1e-5): {value!r}"
        )
    kind, *args = value
    kinds = {"constant": 1, "normal": 2, "gaussian": 2, "lognormal": 2, "poly": 2}
    kind = one_of(kind, "radius distribution", list(kinds))
    kind = "normal" if kind == "gaussian" else kind
    if len(args) != kinds[kind]:
        raise ConfigError(f"radius ('{kind}', ...) takes {kinds[kind]} values, got {len(args)}: {value!r}")
    if kind == "poly":
        radii, weights = (tuple(finite_number(v, "radius poly") for v in seq) for seq in args)
        if len(radii) != len(weights) or not radii:
            raise ConfigError(f"radius ('poly', radii, weights) needs as many weights as radii: {value!r}")
        if min(radii) <= 0 or min(weights) < 0 or sum(weights) <= 0:
            raise ConfigError(f"radius ('poly', ...): radii must be > 0 and weights >= 0: {value!r}")
        total = sum(weights)
        check_span(value, min(radii), max(radii))
        return RadiusDistribution(kind, radii, tuple(w / total for w in weights))
    numbers = tuple(finite_number(v, f"radius {kind}") for v in args)
    if kind == "lognormal" and numbers[0] > 0 and numbers[1] >= 0:  # in logs: exp(3 sigma) may overflow
        low, high = (math.log10(numbers[0]) + sign * 3 * numbers[1] / math.log(10) for sign in (-1, 1))
        if low < -300 or high > 300:
            check_span(value, 0.0, math.inf, (f"1e{low:.0f}", f"1e{high:.0f}"))
    dist = RadiusDistribution(kind, numbers)
    if numbers[0] <= 0 or (len(numbers) > 1 and numbers[1] < 0) or dist.min <= 0:
        raise ConfigError(f"radius {value!r} allows radii <= 0 (the distribution is cut at 3 sigma)")
    check_span(value, dist.min, dist.max)
    return dist


@dataclass(frozen=True)
class Species:
    """A particle component: shape style, material, density and size distribution.

    ``style='multisphere'``: each particle is the rigid clump of ``spheres``, ``(x, y, z, r)``
    in the particle's own frame; ``radius`` is then the largest sphere's radius.
    """

    type: int
    material: Mapping[str, float]
    density: float
    radius: RadiusDistribution
    style: str = "sphere"
    spheres: tuple[tuple[float, ...], ...] = ()


SPECIES_KEYS = ("style", "material", "density", "radius")
#: The keys of multisphere species: a ``function`` giving the spheres, or a tablet.
MULTISPHERE_KEYS = ("function", "nspheres", "length")
SPECIES_STYLES = ("sphere", "multisphere", "multisphere/tablet")
#: The most spheres a multisphere tablet may have.
MAX_SPHERES = 1000


def tablet(nspheres: int, radius: float, length: float) -> tuple[tuple[float, float, float, float], ...]:
    """A cylindrical tablet of ``length`` along x made of ``nspheres`` spheres of ``radius``,
    evenly spaced and centred on the origin (PyGran 1.x's ``template_tablet``)."""
    spacing = (length - 2 * radius) / (nspheres - 1)
    return tuple((-length / 2 + radius + i * spacing, 0.0, 0.0, radius) for i in range(nspheres))


def _multisphere(value: Mapping[str, Any], index: int, style: str) -> tuple[tuple[float, ...], ...]:
    """The spheres of a multisphere species, from its ``function`` or its tablet keys."""
    where = f"species {index} ({style})"
    if "function" in value:
        extra = [key for key in ("nspheres", "length", "radius") if key in value]
        if style == "multisphere/tablet" or extra:
            raise ConfigError(
                f"{where}: 'function' gives the spheres; leave out {', '.join(extra) or 'the tablet style'}"
            )
        function = value["function"]
        if not callable(function):
            raise ConfigError(f"{where}: 'function' must be a function returning [(x, y, z, r), ...]")
        try:
            inspect.signature(function).bind()
        except TypeError:
            raise ConfigError(f"{where}: 'function' must take no arguments") from None
        except ValueError:
            pass  # a builtin without a signature: call it
        spheres = function()
        if isinstance(spheres, (str, bytes)) or not isinstance(spheres, Sequence) or not spheres:
            raise ConfigError(f"{where}: 'function' must return a list of (x, y, z, r), got {spheres!r}")
        clean = tuple(number_tuple(sphere, f"{where} sphere {k}", 4) for k, sphere in enumerate(spheres))
        if min(r for *_, r in clean) <= 0:
            raise ConfigError(f"{where}: every sphere of 'function' needs r > 0")
        for k, (*_, r) in enumerate(clean):
            check_radius(r, f"{where}: the radius of sphere {k}")
        return clean
    missing = [key for key in ("nspheres", "radius", "length") if key not in value]
    if missing:
        raise ConfigError(
            f"{where}: give 'function' returning [(x, y, z, r), ...], or a tablet: nspheres, radius and "
            f"length (missing {', '.join(missing)})"
        )
    count = value["nspheres"]
    if not is_integer(count) or not 2 <= count <= MAX_SPHERES:
        raise ConfigError(f"{where}: nspheres must be a whole number from 2 to {MAX_SPHERES}, got {count!r}")
    radius = check_radius(value["radius"], f"{where} radius")
    length = positive_float(value["length"], f"{where} length")
    if not 2 * radius < length <= 2 * radius * count:
        raise ConfigError(
            f"{where}: length must exceed one diameter ({2 * radius:g}) and be at most nspheres diameters "
            f"({2 * radius * count:g}) so that the spheres touch; got {length:g}"
        )
    return tablet(int(count), radius, length)


def parse_species(value: Any, index: int) -> Species:
    if not isinstance(value, Mapping):
        raise ConfigError(f"species {index} must be a dict with keys {SPECIES_KEYS}, got {value!r}")
    style = one_of(value.get("style", "sphere"), f"species {index} style", SPECIES_STYLES)
    known = SPECIES_KEYS if style == "sphere" else SPECIES_KEYS + MULTISPHERE_KEYS
    for key in value:
        if key not in known and key in MULTISPHERE_KEYS:
            raise ConfigError(
                f"species {index}: {key!r} is for multisphere species; add 'style': 'multisphere'"
            )
    check_keys(f"species {index} keyword", value, known)
    if "material" not in value or (style == "sphere" and "radius" not in value):
        raise ConfigError(
            f"species {index} needs 'material'" + (" and 'radius'" if style == "sphere" else "")
        )
    material = materials.validate(value["material"])
    density = value.get("density", material.get("density"))
    if density is None:
        raise ConfigError(f"species {index}: give 'density' or a material with 'density'")
    spheres: tuple[tuple[float, ...], ...] = ()
    if style == "sphere":
        radius = parse_radius(value["radius"])
    else:
        spheres = _multisphere(value, index, style)
        radius = RadiusDistribution("constant", (max(sphere[-1] for sphere in spheres),))
    return Species(
        index,
        material,
        positive_float(density, f"species {index} density"),
        radius,
        "sphere" if style == "sphere" else "multisphere",
        spheres,
    )


# -- meshes, output ------------------------------------------------------------------------


@dataclass(frozen=True)
class ServoSpec:
    """A servo wall (``mtype='mesh/surface/stress/servo'``, LIGGGHTS' servo mesh module): the
    mesh moves along ``axis`` (``control='force'``; rotates about it through ``com`` for
    ``'torque'``) at up to ``vel_max`` m/s so that the force (N) or torque (N m) the particles
    exert on it along the axis comes to ``target``. ``com`` is the reference point (its
    centre of mass) in the placed mesh's frame. The controller is LIGGGHTS': PID with gains
    ``kp``, ``ki``, ``kd`` (LIGGGHTS' defaults 0.01, 0, 0), or ``mode='auto'`` with ``ratio``.
    """

    com: Vector
    control: str
    axis: Vector
    target: float
    vel_max: float
    kp: float = 0.01
    ki: float = 0.0
    kd: float = 0.0
    mode: str = "pid"
    ratio: float | None = None


@dataclass(frozen=True)
class MeshSpec:
    """A triangle-mesh wall read from an STL file and placed: its points ``p`` become
    ``scale * R p + translate``, ``R`` the rotation by ``rotate = (axis, angle in degrees)``
    about the origin. ``wall``: a wall from the first run (PyGran 1.x's ``'import'``);
    ``servo``: the servo settings of a ``mesh/surface/stress/servo`` mesh; ``inscribed``: the
    primitive region inside a mesh a geometry builder made (see
    :class:`~pygran_core.simulation.geometry.Surface`), as placed."""

    name: str
    file: Path
    material: Mapping[str, float]
    mtype: str = "mesh/surface"
    scale: float = 1.0
    rotate: tuple[Vector, float] | None = None  # (axis, angle in degrees)
    translate: Vector = (0.0, 0.0, 0.0)
    wall: bool = True
    servo: ServoSpec | None = None
    inscribed: tuple[object, ...] | None = None

    def triangles(self) -> np.ndarray:
        """The mesh's triangles ``(T, 3, 3)`` in place: scaled, rotated about the origin, then
        translated (the order of LIGGGHTS' ``scale``, ``rotate``, ``move`` keywords)."""
        if not self.file.is_file():
            raise ReadError(f"File not found: {self.file.resolve()}")
        frame = STLTrajectory([self.file], scale=self.scale).read_frame(0)
        points, cells = frame.arrays["points"], frame.arrays["cells"]
        if self.rotate is not None:
            points = points @ rotation_matrix(*self.rotate).T
        return points[cells[:, :3]] + np.asarray(self.translate)


MESH_KEYS = (
    "file",
    "triangles",
    "material",
    "mtype",
    "args",
    "import",
    "scale",
    "rotate",
    "translate",
    "move",
)
MESH_TYPES = ("mesh/surface", "mesh/surface/stress", "mesh/surface/stress/servo")
#: The placement keywords of a mesh's ``args``, applied in the order written (LIGGGHTS'
#: ``fix mesh/surface`` keywords): ``move dx dy dz``, ``scale s``, ``rotate axis ax ay az angle a``.
PLACEMENT_KEYS = ("move", "scale", "rotate")
#: The servo keywords of a ``mesh/surface/stress/servo`` mesh's ``args`` and how many values each takes.
SERVO_KEYS = {
    "com": 3,
    "ctrlPV": 1,
    "axis": 3,
    "target_val": 1,
    "vel_max": 1,
    "kp": 1,
    "ki": 1,
    "kd": 1,
    "mode": 1,
    "ratio": 1,
}


def rotation_matrix(axis: Sequence[float], degrees: float) -> np.ndarray:
    """The right-handed rotation by ``degrees`` about ``axis`` (Rodrigues' formula)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    angle = math.radians(degrees)
    return np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross


def _words(args: Any, name: str) -> list[Any]:
    """A mesh's ``args`` as one list of LIGGGHTS words, in the order written: a dict
    (``{'scale': 1e-3, 'rotate': ('axis', 0, 1, 0, 'angle', 90), 'move': (0, 0, 1)}``),
    strings (``('scale 1e-3', 'move 0 0 1')``) or a mix of strings and numbers."""
    if isinstance(args, Mapping):
        items: list[Any] = []
        for key, value in args.items():
            items.append(key)
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
                value = [value]
            for item in value:  # the top-level-rotate form (axis, angle) nests a vector
                items.extend(item if isinstance(item, Sequence) and not isinstance(item, str) else [item])
        args = items
    elif isinstance(args, str) or not isinstance(args, Sequence):
        args = [args]
    words: list[Any] = []
    for item in args:
        if isinstance(item, str):
            words.extend(item.split())
        elif is_real(item):
            words.append(item)
        else:
            raise ConfigError(
                f"mesh {name!r} args: {item!r} is neither a keyword nor a number; give args as a dict "
                "such as {'scale': 1e-3, 'move': (0, 0, 0.01)} or LIGGGHTS words ('scale 1e-3', ...)"
            )
    return words


def _numbers(words: list[Any], start: int, count: int, name: str, key: str) -> tuple[float, ...]:
    values = words[start : start + count]
    try:
        numbers = tuple(float(w) for w in values)
    except (TypeError, ValueError):
        numbers = ()
    if len(numbers) != count or not all(math.isfinite(v) for v in numbers):
        raise ConfigError(
            f"mesh {name!r} args: {key!r} takes {count} number(s), got {values!r}"
            + (" (LIGGGHTS' form: rotate axis ax ay az angle degrees)" if key == "rotate" else "")
        )
    return numbers


def parse_placement(args: Any, name: str, servo: bool) -> tuple[list[tuple[Any, ...]], dict[str, Any]]:
    """Read a mesh's ``args``: the placement steps ``('move', v)``, ``('scale', s)``,
    ``('rotate', axis, degrees)`` in the order written, and the servo keywords (allowed
    when ``servo``). Any other keyword is a :class:`ConfigError` naming it."""
    words = _words(args, name)
    known = PLACEMENT_KEYS + (tuple(SERVO_KEYS) if servo else ())
    steps: list[tuple[Any, ...]] = []
    servo_values: dict[str, Any] = {}
    i = 0
    while i < len(words):
        key = words[i]
        if key == "translate":
            key = "move"
        if not isinstance(key, str) or key not in known:
            if isinstance(key, str) and key in SERVO_KEYS:
                raise ConfigError(
                    f"mesh {name!r} args: {key!r} is a servo keyword; it needs "
                    "mtype='mesh/surface/stress/servo'"
                )
            raise unknown_key(f"mesh {name!r} argument", str(key), known)
        if key == "move":
            steps.append(("move", _numbers(words, i + 1, 3, name, key)))
            i += 4
        elif key == "scale":
            (factor,) = _numbers(words, i + 1, 1, name, key)
            if factor <= 0:
                raise ConfigError(f"mesh {name!r} args: scale must be > 0, got {factor}")
            steps.append(("scale", factor))
            i += 2
        elif key == "rotate":
            if words[i + 1 : i + 2] != ["axis"] or words[i + 5 : i + 6] != ["angle"]:
                raise ConfigError(
                    f"mesh {name!r} args: rotate is ('axis', ax, ay, az, 'angle', degrees), got "
                    f"{words[i + 1 : i + 7]!r}"
                )
            axis = _numbers(words, i + 2, 3, name, key)
            if not any(axis):
                raise ConfigError(f"mesh {name!r} args: the rotation axis must not be zero")
            steps.append(("rotate", axis, _numbers(words, i + 6, 1, name, key)[0]))
            i += 7
        else:
            count = SERVO_KEYS[key]
            values = words[i + 1 : i + 1 + count]
            if key not in ("ctrlPV", "mode"):
                values = list(_numbers(words, i + 1, count, name, key))
            elif len(values) != 1:
                raise ConfigError(f"mesh {name!r} args: {key!r} takes one word")
            servo_values[key] = values if count > 1 else values[0]
            i += 1 + count
    return steps, servo_values


def compose(steps: list[tuple[Any, ...]]) -> tuple[float, tuple[Vector, float] | None, Vector]:
    """``(scale, rotate, translate)`` equal to the placement ``steps`` applied in order: a
    uniform scale commutes with rotations, so any order comes to ``p -> s R p + t``."""
    scale, rotation, shift = 1.0, np.eye(3), np.zeros(3)
    for step in steps:
        if step[0] == "move":
            shift = shift + np.asarray(step[1])
        elif step[0] == "scale":
            scale, shift = scale * step[1], shift * step[1]
        else:
            turn = rotation_matrix(step[1], step[2])
            rotation, shift = turn @ rotation, turn @ shift
    turns = [step for step in steps if step[0] == "rotate"]
    if len(turns) == 1:  # as given, to the last digit
        rotate: tuple[Vector, float] | None = (turns[0][1], turns[0][2])
    else:
        from scipy.spatial.transform import Rotation  # loaded on first use: import pygran_core stays light

        rotvec = Rotation.from_matrix(rotation).as_rotvec()
        angle = float(np.linalg.norm(rotvec))
        rotate = None
        if angle >= 1e-12:
            rotate = (vector((rotvec / angle).tolist(), "mesh rotation axis"), math.degrees(angle))
    return scale, rotate, vector(shift.tolist(), "mesh translation")


def parse_servo(values: Mapping[str, Any], name: str) -> ServoSpec:
    """The servo settings of mesh ``name`` from its ``args`` (LIGGGHTS' keywords)."""
    missing = [key for key in ("com", "ctrlPV", "axis", "target_val", "vel_max") if key not in values]
    if missing:
        raise ConfigError(
            f"mesh {name!r} is a servo wall (mesh/surface/stress/servo): give {', '.join(missing)} in its "
            "args, e.g. {'com': (0, 0, 0.01), 'ctrlPV': 'force', 'axis': (0, 0, -1), 'target_val': 5.0, "
            "'vel_max': 0.1}"
        )
    axis = np.asarray(values["axis"], float)
    if not np.linalg.norm(axis) > 0:
        raise ConfigError(f"mesh {name!r}: the servo axis must not be zero")
    target = values["target_val"]
    if target == 0:
        raise ConfigError(f"mesh {name!r}: the servo target_val (force or torque) must not be 0")
    mode = one_of(values.get("mode", "pid"), f"mesh {name!r} servo mode", ("pid", "auto"))
    gains = {k: values.get(k, ServoSpec.__dataclass_fields__[k].default) for k in ("kp", "ki", "kd")}
    ratio = values.get("ratio")
    if mode == "auto" and not (ratio is not None and ratio > 0):
        raise ConfigError(f"mesh {name!r}: the servo mode 'auto' needs ratio > 0")
    if mode == "pid" and (min(gains.values()) < 0 or not any(gains.values())):
        raise ConfigError(f"mesh {name!r}: the servo gains kp, ki, kd must be >= 0, not all 0; got {gains}")
    return ServoSpec(
        com=tuple(values["com"]),
        control=one_of(values["ctrlPV"], f"mesh {name!r} servo ctrlPV", ("force", "torque")),
        axis=vector((axis / np.linalg.norm(axis)).tolist(), f"mesh {name!r} servo axis"),
        target=float(target),
        vel_max=positive_float(values["vel_max"], f"mesh {name!r} servo vel_max"),
        mode=mode,
        ratio=ratio,
        **gains,
    )


def check_mesh_file(path: Path, name: str) -> None:
    """Refuse, saying which, a mesh ``file`` that is missing, a folder or not a regular file
    (a device such as ``/dev/zero`` or a pipe, which would be read without end)."""
    if not path.exists():
        raise ConfigError(f"mesh {name!r}: file {path} does not exist")
    if path.is_dir():
        raise ConfigError(f"mesh {name!r}: {path} is a folder, not an STL file: name the file in it")
    if not path.is_file():
        raise ConfigError(
            f"mesh {name!r}: {path} is not a regular file (a device, pipe or socket): give an STL file"
        )


#: Mesh files read as text tables of triangles (nine columns a row, :func:`read_triangles`).
TRIANGLE_TABLES = (".txt", ".txt.gz")


def parse_mesh(name: str, value: Any, base: Path, output: Path | None = None) -> MeshSpec:
    """A mesh of ``mesh={name: value}``: ``file`` (STL, or a text table of triangles ending in
    ``.txt`` or ``.txt.gz``) or ``triangles`` (a
    :class:`~pygran_core.simulation.geometry.Surface` or an ``(M, 3, 3)`` array in metres,
    written to ``<output>/mesh-<name>.stl`` for the engines), ``material``, ``mtype``, ``args``
    (placement and servo keywords, see :func:`parse_placement`) and ``import`` (``False``: not
    a wall until ``setupWall(wtype='mesh', mesh=name)``); ``scale``, ``rotate``, ``move`` may
    also stand beside ``args``, applied after it."""
    if not isinstance(value, Mapping):
        raise ConfigError(f"mesh {name!r} must be a dict with keys such as 'file' and 'material'")
    check_keys(f"mesh {name!r} keyword", value, MESH_KEYS)
    if ("file" in value) == ("triangles" in value):
        raise ConfigError(
            f"mesh {name!r} needs either 'file' (an STL file) or 'triangles' (a geometry surface or an "
            "(M, 3, 3) array in metres), not both"
            if "file" in value
            else f"mesh {name!r} needs 'file' (an STL file) or 'triangles' (a geometry surface, such as "
            "simulation.geometry.drum(...), or an (M, 3, 3) array in metres)"
        )
    inscribed = None
    if isinstance(value.get("file"), (str, os.PathLike)) and str(value["file"]).endswith(TRIANGLE_TABLES):
        table = Path(file_name(value["file"], f"mesh {name!r} file"))
        triangles = read_triangles(table if table.is_absolute() else base / table)
        value = {key: v for key, v in value.items() if key != "file"} | {"triangles": triangles}
    if "triangles" in value:
        surface = geometry.as_surface(value["triangles"], name)
        inscribed = surface.inscribed
        folder = output if output is not None else base
        folder.mkdir(parents=True, exist_ok=True)
        value = {**value, "file": surface.write(folder / f"mesh-{name}.stl")}
    if not isinstance(value["file"], (str, os.PathLike)):
        raise ConfigError(f"mesh {name!r}: 'file' must be a path to an STL file, got {value['file']!r}")
    path = Path(file_name(value["file"], f"mesh {name!r} file"))
    path = path if path.is_absolute() else base / path
    check_mesh_file(path, name)
    mtype = one_of(value.get("mtype", "mesh/surface"), f"mesh {name!r} mtype", MESH_TYPES)
    servo = mtype.endswith("/servo")
    steps, servo_values = parse_placement(value.get("args", ()), name, servo)
    for key in ("scale", "rotate", "translate", "move"):
        if key in value:
            steps += parse_placement({key: value[key]}, name, servo=False)[0]
    scale, rotate, translate = compose(steps)
    wall = value.get("import", True)
    if not isinstance(wall, bool):
        raise ConfigError(
            f"mesh {name!r}: 'import' is True (a wall from the first run) or False, got {wall!r}"
        )
    return MeshSpec(
        name=name,
        file=path,
        material=materials.validate(value.get("material", {})) if "material" in value else {},
        mtype=mtype,
        scale=scale,
        rotate=rotate,
        translate=translate,
        wall=wall,
        servo=parse_servo(servo_values, name) if servo else None,
        inscribed=inscribed if (scale, rotate, translate) == (1.0, None, (0.0, 0.0, 0.0)) else None,
    )


#: How far (a fraction of the box's longest side) a point may lie beyond a face of the box and
#: still count as on it: rounding in the script's arithmetic, not a mistake.
BOX_TOLERANCE = 1e-9
#: A mesh this many times larger than the box is probably in other units (millimetres).
UNIT_MISMATCH = 10.0


def check_mesh_in_box(mesh: MeshSpec, domain: Domain) -> None:
    """Refuse a mesh with triangles outside the box: those whose centre lies beyond a face that
    is not shrink-wrapped. LIGGGHTS stops on such a mesh (its elements belong to the part of
    the domain holding their centre); the other engines would keep a wall no particle reaches.
    A mesh much larger than the box is probably in millimetres: the message says so."""
    triangles = mesh.triangles()
    centres = triangles.mean(axis=1)
    box = np.array(domain.box, float)
    lengths = box[:, 1] - box[:, 0]
    tol = BOX_TOLERANCE * float(lengths.max())
    lower = np.array([flag[0] not in "sm" for flag in domain.boundary])
    upper = np.array([flag[-1] not in "sm" for flag in domain.boundary])
    outside = np.any((lower & (centres < box[:, 0] - tol)) | (upper & (centres > box[:, 1] + tol)), axis=1)
    count = int(outside.sum())
    if not count:
        return
    points = triangles.reshape(-1, 3)
    size = float(np.max(points.max(axis=0) - points.min(axis=0)))
    if size > UNIT_MISMATCH * float(lengths.max()):
        hint = (
            f"the mesh is {size / float(lengths.max()):.3g} times the box's longest side: if its file is "
            f"in millimetres, add 'scale': 1e-3 to mesh {mesh.name!r}"
        )
    else:
        hint = "move it into the box with 'move': (dx, dy, dz), scale it with 'scale', or enlarge the box"
    span = ", ".join(
        f"{axis} {lo:.4g} to {hi:.4g}"
        for axis, lo, hi in zip("xyz", centres.min(axis=0), centres.max(axis=0))
    )
    box_text = ", ".join(f"{axis} {lo:g} to {hi:g}" for axis, (lo, hi) in zip("xyz", domain.box))
    raise ConfigError(
        f"mesh {mesh.name!r}: {count} of its {len(triangles)} triangles lie outside the box (triangle "
        f"centres {span}; box {box_text}), where no particle reaches them and LIGGGHTS stops: {hint}"
    )


@dataclass(frozen=True)
class TrajectorySpec:
    """Trajectory output: particle file ``pfile``, mesh file ``mfile`` and contacts file
    ``cfile`` every ``freq`` steps.

    The file extension picks the writer (``.dump``, ``.h5``, ``.vtk``); ``None`` writes nothing.
    ``cfile`` (engines with the capability ``contact-output``) holds the contact records of
    :mod:`~pygran_core.formats.contacts`: a ``.dump`` is written as LIGGGHTS' ``dump local``,
    an H5MD name equal to ``pfile`` puts them in the particle file's ``/contacts`` group.
    ``sel`` is ``"all"`` or a species number; ``args`` the particle columns (by default with
    ``mass`` and ``density``, which analysis reads instead of asking, and the angular
    velocities, which viewers show). ``style``
    ``'custom/vtk'`` goes with a ``.vtk`` pfile. ``margs`` (the columns of LIGGGHTS' mesh dump)
    and ``dump_modify`` (of its ``.dump`` file) are LIGGGHTS' own: engines without the
    capability ``liggghts-dump`` refuse them when they differ from the defaults.
    """

    freq: int = 1000
    pfile: Path | None = None
    mfile: Path | None = None
    cfile: Path | None = None
    sel: str | int = "all"
    style: str = "custom"
    args: tuple[str, ...] = (
        *("id", "type", "x", "y", "z", "radius", "mass", "density"),
        *("vx", "vy", "vz", "fx", "fy", "fz", "omegax", "omegay", "omegaz"),
    )
    margs: tuple[str, ...] = ("id", "stress")
    dump_modify: tuple[str, ...] = ()


TRAJ_KEYS = ("freq", "pfile", "mfile", "cfile", "dir", "sel", "style", "args", "margs")
#: File names ``traj`` ``cfile`` may take: LIGGGHTS' ``dump local`` text, or H5MD.
CONTACT_SUFFIXES = (".dump", ".h5", ".h5md", ".hdf5")


def parse_traj(
    value: Any, output: Path, dump_modify: Any, notes: list[str] | None = None, *, meshes: bool = False
) -> TrajectorySpec:
    """``traj`` and ``dump_modify`` (``meshes``: whether the simulation has meshes). Settings
    that cannot apply are refused: ``dump_modify`` without a ``.dump`` pfile, ``margs`` without
    meshes and an mfile, style ``'custom/vtk'`` without a ``.vtk`` pfile, style ``'atom'``."""
    value = {} if value is None else value
    if not isinstance(value, Mapping):
        raise ConfigError(f"traj must be a dict with keys {TRAJ_KEYS}, got {value!r}")
    check_keys("traj keyword", value, TRAJ_KEYS)
    directory = output / file_name(value.get("dir", "."), "traj dir")
    files = {}
    for key, default in (("pfile", "traj.dump"), ("mfile", None), ("cfile", None)):
        name = value.get(key, default)
        files[key] = None if name is None else directory / file_name(name, f"traj {key}")
    cfile = files["cfile"]
    if cfile is not None and (cfile.suffix not in CONTACT_SUFFIXES or cfile == files["mfile"]):
        raise ConfigError(
            f"traj cfile {value['cfile']!r}: contact records are written as a .dump (LIGGGHTS' dump local) "
            "or into an H5MD file (.h5, .h5md, .hdf5), which may be the pfile: give such a name"
        )
    if cfile is not None and cfile == files["pfile"] and cfile.suffix == ".dump":
        raise ConfigError(
            f"traj cfile {value['cfile']!r} is the pfile, but a .dump holds particles or contacts, not both: "
            "give the contacts their own .dump (such as 'contacts.dump'), or make both one .h5 file"
        )
    sel = value.get("sel", "all")
    if not (isinstance(sel, str) and sel == "all") and (not is_integer(sel) or sel < 1):
        raise ConfigError(f"traj sel must be 'all' or a species number (1, 2, ...), got {sel!r}")
    style = value.get("style", "custom")
    if isinstance(style, str) and style == "atom":
        raise UnsupportedFeature(
            "traj style 'atom': LIGGGHTS 3.8 has no dump style atom, nor does any other engine write one; "
            "use style 'custom' with args ('id', 'type', 'x', 'y', 'z')"
        )
    style = one_of(style, "traj style", ("custom", "custom/vtk"))
    if style == "custom/vtk" and (files["pfile"] is None or not str(files["pfile"]).endswith(".vtk")):
        raise ConfigError(
            f"traj style 'custom/vtk' writes legacy VTK files, but pfile is "
            f"{value.get('pfile', 'traj.dump')!r}: give pfile a name ending in .vtk (the file's extension "
            "picks the format)"
        )
    modify = () if dump_modify is None else words(dump_modify, "dump_modify")
    if modify and not str(files["pfile"] or "").endswith(".dump"):
        raise ConfigError(
            f"dump_modify {list(modify)} applies to the .dump file LIGGGHTS writes, but traj pfile is "
            f"{value.get('pfile', 'traj.dump')!r}: give pfile a name ending in .dump"
        )
    margs = columns(value.get("margs", TrajectorySpec.margs), "traj margs")
    if margs != TrajectorySpec.margs and (files["mfile"] is None or not meshes):
        raise ConfigError(
            f"traj margs {list(margs)} are the columns of the meshes' trajectory, which needs meshes and "
            "traj mfile (a name such as 'mesh*.vtk')"
        )
    return TrajectorySpec(
        freq=step_count(value.get("freq", 1000), "traj freq", notes),
        sel=sel,
        style=style,
        args=columns(value.get("args", TrajectorySpec.args), "traj args"),
        margs=margs,
        dump_modify=modify,
        **files,
    )


@dataclass(frozen=True)
class RestartSpec:
    """Checkpoints every ``freq`` steps in ``directory``; ``resume`` from ``lastfile`` or the newest."""

    freq: int
    directory: Path
    fname: str = "restart.h5"
    resume: bool = False
    lastfile: Path | None = None


def parse_restart(value: Any, output: Path, notes: list[str] | None = None) -> RestartSpec | None:
    """The manual's 5-tuple ``(freq, dir, fname, resume, lastfile)``, a dict, or a frequency."""
    if value is None:
        return None
    if is_real(value):
        value = (value,)
    if isinstance(value, Mapping):
        check_keys("restart keyword", value, ("freq", "dir", "fname", "resume", "lastfile"))
        value = tuple(value.get(k) for k in ("freq", "dir", "fname", "resume", "lastfile"))
    if isinstance(value, str) or not isinstance(value, Sequence) or not 1 <= len(value) <= 5:
        raise ConfigError(
            f"restart must be (freq, dir, fname, resume, lastfile), a dict or an int: {value!r}"
        )
    padded: tuple[Any, ...] = (*value, *([None] * (5 - len(value))))
    freq, directory, fname, resume, lastfile = padded
    directory = output / file_name(directory or "restart", "restart dir")
    if resume not in (None, True, False):
        raise ConfigError(f"restart resume must be True or False, got {resume!r}")
    return RestartSpec(
        freq=step_count(freq, "restart freq", notes),
        directory=directory,
        fname=str(file_name(fname or "restart.h5", "restart fname")),
        resume=bool(resume),
        lastfile=None if lastfile in (None, "None") else directory / file_name(lastfile, "restart lastfile"),
    )


# -- the whole simulation --------------------------------------------------------------


@dataclass(frozen=True)
class ProgressSpec:
    """How runs report their progress: ``show`` a bar on a terminal (None: when stderr is
    one); a line every ``every`` seconds of a run in ``pygran.log``, and on stderr off a
    terminal; ``steps``, the script's steps over all its runs, gives one ETA for the script."""

    show: bool | None = None
    every: float = 30.0
    steps: int | None = None


PROGRESS_KEYS = ("show", "every", "steps")


def parse_progress(value: Any) -> ProgressSpec:
    """``progress=True``, ``False``, ``None`` (a bar on a terminal), or a dict such as
    ``{'every': 10, 'steps': 60000}`` (see :class:`ProgressSpec`)."""
    if not isinstance(value, Mapping):
        return ProgressSpec(show=optional_bool(value, "progress"))
    check_keys("progress keyword", value, PROGRESS_KEYS)
    steps = value.get("steps")
    return ProgressSpec(
        show=optional_bool(value.get("show"), "progress show"),
        every=positive_float(value.get("every", ProgressSpec.every), "progress every (seconds)"),
        steps=None if steps is None else positive_int(steps, "progress steps (the script's total)"),
    )


@dataclass(frozen=True)
class SimulationSpec:
    """Everything ``simulation.DEM(**params)`` was given, validated."""

    engine: str
    model: type[ContactModel]
    output: Path
    domain: Domain
    species: tuple[Species, ...] = ()
    meshes: tuple[MeshSpec, ...] = ()
    #: ``pairs=``: per-pair material values over the mixing rules (see :mod:`.materials`).
    pairs: Pairs = ()
    gravity: Gravity | None = None
    dt: float | None = None
    seed: int = 12345
    units: str = "si"
    nns_type: str = "bin"
    nns_skin: float | None = None
    traj: TrajectorySpec = field(default_factory=TrajectorySpec)
    restart: RestartSpec | None = None
    nsim: int = 1
    threads: int | None = None
    nprocs: int | None = None
    progress: ProgressSpec = field(default_factory=lambda: ProgressSpec())
    #: With ``nSim=k > 1``: the k runs, each with its own parameters and output directory.
    runs: tuple[SimulationSpec, ...] = ()
    #: The script's own keys (not simulation keywords), kept by ``DEM`` and named in the log.
    user_keys: tuple[str, ...] = ()
    #: What parsing changed in what was given (step counts truncated), for the log.
    notes: tuple[str, ...] = ()

    @property
    def max_radius(self) -> float:
        return max((s.radius.max for s in self.species), default=0.0)

    @property
    def min_radius(self) -> float:
        return min((s.radius.min for s in self.species), default=0.0)

    @property
    def skin(self) -> float:
        """Neighbour-list skin: ``nns_skin``, else the smallest particle radius. The small
        particles set it: a skin of the largest radius (a 10 mm ball in a bed of 1 mm beads)
        makes every small particle's list many times longer, for no fewer rebuilds."""
        return self.nns_skin if self.nns_skin is not None else self.min_radius


SIMULATION_KEYS = (
    "engine",
    "model",
    "nSim",
    "units",
    "nns_type",
    "nns_skin",
    "dim",
    "box",
    "boundary",
    "gravity",
    "species",
    "mesh",
    "pairs",
    "output",
    "restart",
    "dump_modify",
    "traj",
    "dt",
    "seed",
    "threads",
    "nprocs",
    "progress",
)


#: Keywords of PyGran 1.x that PyGran does not take, with what to do instead.
REFUSED_KEYS = {
    "read_data": "read the particles with analysis.System and create them with createParticles",
    "cylinder": "give a box around the cylinder and a cylinder wall: setupWall(axis=..., radius=...)",
}


def split_keys(params: Mapping[str, Any]) -> tuple[str, ...]:
    """The keys of ``params`` that are the script's own (``'stages'``, ``'nsteps'``, ...).

    A key within one or two edits of a simulation keyword is taken for a misspelling of it
    (``'gravty'``) and is a :class:`ConfigError` naming the keyword, as are the keywords of
    PyGran 1.x that PyGran does not take (:data:`REFUSED_KEYS`).
    """
    own = []
    for key in params:
        if key in SIMULATION_KEYS:
            continue
        if key in REFUSED_KEYS:
            raise ConfigError(
                f"The simulation keyword {key!r} of PyGran 1.x is not supported: {REFUSED_KEYS[key]}"
            )
        if not isinstance(key, str):
            raise ConfigError(f"Simulation keywords are strings, got {key!r}")
        close = near_miss(key, SIMULATION_KEYS)
        if close is not None:
            raise ConfigError(
                f"Unknown simulation keyword {key!r}. Did you mean {close!r}? A key of the script's own "
                "must differ from every simulation keyword by more than two letters."
            )
        own.append(key)
    return tuple(own)


#: The most runs ``nSim`` may ask for.
MAX_NSIM = 10000


def default_output(model: type) -> str:
    """The manual's default output folder: the model's name and the time of day. Under
    ``mpirun`` rank 0 reads the clock and every rank takes its name, so that all ranks (and
    the ``nSim`` runs) write into one folder."""
    return rank0_value(lambda: f"{model.__name__}-{time.strftime('%d%m%Y-%H%M%S')}")


def _per_run(value: Any, index: int, nsim: int, where: str) -> Any:
    if not isinstance(value, list):
        return value
    if len(value) != nsim:
        raise ConfigError(f"{where} gives {len(value)} values (a list), but nSim={nsim} needs one per run")
    return value[index]


def run_params(params: Mapping[str, Any], index: int, nsim: int) -> dict[str, Any]:
    """The keywords of run ``index`` of ``nSim`` runs: each list-valued species entry (or
    material entry of a species) gives one value per run; the run writes to ``<output>/run<index>``
    (``params`` must give ``output``)."""
    species_in = params.get("species", ())
    species_in = (species_in,) if isinstance(species_in, Mapping) else species_in
    species = []
    for k, entry in enumerate(species_in, start=1):
        if isinstance(entry, Mapping):
            entry = {key: _per_run(v, index, nsim, f"species {k} {key!r}") for key, v in entry.items()}
            if isinstance(entry.get("material"), Mapping):
                entry["material"] = {
                    key: _per_run(v, index, nsim, f"species {k} material {key!r}")
                    for key, v in entry["material"].items()
                }
        species.append(entry)
    return {**params, "species": tuple(species), "output": str(Path(params["output"]) / f"run{index}")}


def parse_simulation(params: Mapping[str, Any], engine: str, model: type[ContactModel]) -> SimulationSpec:
    """Validate ``simulation.DEM`` keywords; ``engine`` and ``model`` are already resolved.
    Keys that are not simulation keywords are the script's own (see :func:`split_keys`).

    With ``nSim=k > 1`` the spec holds the k runs in :attr:`SimulationSpec.runs` (see
    :func:`run_params`); its own fields are those of run 0 but for ``output`` and ``nsim``.
    """
    user_keys = split_keys(params)
    nsim = positive_int(params.get("nSim", 1), "nSim")
    if nsim > MAX_NSIM:
        raise ConfigError(f"nSim={nsim}: at most {MAX_NSIM} runs, one per group of MPI ranks")
    if nsim > 1:
        output = params["output"] if "output" in params else default_output(model)
        runs = tuple(
            parse_simulation(run_params({**params, "output": output}, i, nsim) | {"nSim": 1}, engine, model)
            for i in range(nsim)
        )
        first = run_params({**params, "output": output}, 0, nsim) | {"nSim": 1, "output": output}
        return replace(parse_simulation(first, engine, model), nsim=nsim, runs=runs)
    if "box" not in params:
        raise ConfigError("box is required: (xmin, xmax, ymin, ymax, zmin, zmax) in metres")
    dim = params.get("dim", 3)
    if not is_integer(dim) or dim != 3:
        raise ConfigError(f"dim={dim!r}: only 3-D simulations are supported")
    units = one_of(params.get("units", "si"), "units", ("si",))
    cwd = Path(os.getcwd())
    output = cwd / file_name(params["output"] if "output" in params else default_output(model), "output")
    species_in = params.get("species", ())
    if isinstance(species_in, Mapping):
        species_in = (species_in,)
    if isinstance(species_in, str) or not isinstance(species_in, Sequence):
        raise ConfigError(
            f"species must be a tuple of dicts ({{'material': ..., 'radius': ...}}, ...), got {species_in!r}"
        )
    meshes_in = params.get("mesh", {})
    meshes_in = {} if meshes_in is None else meshes_in
    if not isinstance(meshes_in, Mapping):
        raise ConfigError("mesh must be a dict of {name: {'file': ..., 'material': ...}}")
    seed = params.get("seed", 12345)
    if not is_integer(seed) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    threads, nprocs = params.get("threads"), params.get("nprocs")
    notes: list[str] = []
    traj = parse_traj(params.get("traj"), output, params.get("dump_modify"), notes, meshes=bool(meshes_in))
    restart = parse_restart(params.get("restart"), output, notes)
    spec = SimulationSpec(
        engine=engine,
        model=model,
        output=output,
        domain=Domain(parse_box(params["box"]), parse_boundary(params.get("boundary", ("f", "f", "f")))),
        species=tuple(parse_species(s, i) for i, s in enumerate(species_in, start=1)),
        meshes=tuple(parse_mesh(name, m, cwd, output) for name, m in meshes_in.items()),
        gravity=None if params.get("gravity") is None else parse_gravity(params["gravity"]),
        dt=None if params.get("dt") is None else positive_float(params["dt"], "dt"),
        seed=int(seed),
        units=units,
        nns_type=one_of(params.get("nns_type", "bin"), "nns_type", ("bin", "nsq", "multi")),
        nns_skin=None if params.get("nns_skin") is None else positive_float(params["nns_skin"], "nns_skin"),
        traj=traj,
        restart=restart,
        nsim=positive_int(params.get("nSim", 1), "nSim"),
        threads=None if threads is None else positive_int(threads, "threads"),
        nprocs=None if nprocs is None else positive_int(nprocs, "nprocs"),
        progress=parse_progress(params.get("progress")),
        user_keys=user_keys,
        notes=tuple(notes),
    )
    for mesh in spec.meshes:
        check_mesh_in_box(mesh, spec.domain)
    meshes = {m.name: bool(m.material) for m in spec.meshes}
    pairs = parse_pairs(params.get("pairs"), len(spec.species), meshes)
    return replace(spec, pairs=pairs) if pairs else spec
