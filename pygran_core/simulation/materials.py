"""The material table every engine reads: per-type properties and per-pair matrices.

Types are the species in order, then the meshes that carry a material of their own (a mesh
without one is made of its wall's species). A pair value given in ``DEM(pairs=...)`` replaces
the mixing rule of :mod:`~pygran_core.simulation.models.mixing` for that pair; every other
pair is mixed. A key a material leaves out takes its value from :data:`DEFAULTS`, unless the
contact model requires it (``ContactModel.required``): then it is a :class:`ConfigError`.
Engines only read the table and rename its keys into their own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pygran_core.errors import ConfigError, unknown_key
from pygran_core.simulation.models import mixing

__all__ = ["DEFAULTS", "PAIR_KEYS", "TYPE_KEYS", "MaterialTable", "build_table", "parse_pairs"]

#: Pair properties: the mixing rule of a pair no ``pairs`` entry gives, and the allowed range.
PAIR_KEYS: Mapping[str, tuple[Callable[..., Any], Callable[[float], bool], str]] = {
    "coefficientRestitution": (mixing.pair_restitution, lambda v: 0 < v <= 1, "in (0, 1]"),
    "coefficientFriction": (mixing.pair_friction, lambda v: v >= 0, ">= 0"),
    "coefficientRollingFriction": (mixing.pair_friction, lambda v: v >= 0, ">= 0"),
    "coefficientRollingViscousDamping": (mixing.pair_friction, lambda v: v >= 0, ">= 0"),
    "cohesionEnergyDensity": (mixing.pair_cohesion, lambda v: v >= 0, ">= 0"),
    "yieldPress": (mixing.pair_yield_pressure, lambda v: v > 0, "> 0"),
}
#: Per-type properties engines combine themselves (Hertz moduli, a model's single velocity).
TYPE_KEYS = ("youngsModulus", "poissonsRatio", "characteristicVelocity")
#: What a material that leaves a key out is taken to have; a key a model requires has none.
DEFAULTS: Mapping[str, float] = {
    "coefficientFriction": 0.0,
    "coefficientRollingFriction": 0.0,
    "coefficientRollingViscousDamping": 0.0,
    "cohesionEnergyDensity": 0.0,
}
#: The keys ``DEM(pairs=...)`` may set for a pair.
PAIR_SETTABLE = (
    "coefficientRestitution",
    "coefficientFriction",
    "coefficientRollingFriction",
    "coefficientRollingViscousDamping",
    "cohesionEnergyDensity",
)

Body = int | str
Pairs = tuple[tuple[tuple[Body, Body], tuple[tuple[str, float], ...]], ...]


def _body(key: Any, n_species: int, meshes: Mapping[str, bool]) -> Body:
    if isinstance(key, Integral) and not isinstance(key, bool):
        if not 1 <= int(key) <= n_species:
            raise ConfigError(f"pairs: species {key} does not exist (species are 1 to {n_species})")
        return int(key)
    if isinstance(key, str):
        if key not in meshes:
            raise unknown_key("pairs mesh", key, sorted(meshes))
        if not meshes[key]:
            raise ConfigError(
                f"pairs: mesh {key!r} has no material of its own (it is made of its wall's species): "
                f"give it 'material' in mesh={{...}} or key the pair by that species"
            )
        return key
    raise ConfigError(f"pairs: {key!r} is neither a species number nor a mesh name")


def parse_pairs(value: Any, n_species: int, meshes: Mapping[str, bool]) -> Pairs:
    """``DEM(pairs={(1, 2): {'coefficientFriction': 0.2}, (1, 'drum'): {...}})`` validated:
    each key two species numbers or names of meshes (``meshes``: name -> has a material), in
    either order; each value a dict of :data:`PAIR_SETTABLE` keys within range."""
    if value is None:
        return ()
    if not isinstance(value, Mapping):
        raise ConfigError(
            "pairs must be a dict {(body, body): {key: value}}, a body a species number or mesh name"
        )
    parsed: dict[tuple[Body, Body], tuple[tuple[str, float], ...]] = {}
    for key, given in value.items():
        if not isinstance(key, tuple) or len(key) != 2:
            raise ConfigError(f"pairs: key {key!r} must be a pair such as (1, 2) or (1, 'drum')")
        a, b = (_body(k, n_species, meshes) for k in key)
        pair = tuple(sorted((a, b), key=lambda body: (isinstance(body, str), str(body))))
        if pair in parsed:
            raise ConfigError(f"pairs: {key!r} is given twice (in either order)")
        if not isinstance(given, Mapping) or not given:
            raise ConfigError(f"pairs {key!r}: expected a dict such as {{'coefficientFriction': 0.2}}")
        values = []
        for name, number in given.items():
            if name not in PAIR_SETTABLE:
                raise unknown_key(f"pairs {key!r} property", str(name), PAIR_SETTABLE)
            _, check, allowed = PAIR_KEYS[name]
            if not isinstance(number, Real) or isinstance(number, bool) or not math.isfinite(number):
                raise ConfigError(f"pairs {key!r} {name}: expected a number, got {number!r}")
            if not check(float(number)):
                raise ConfigError(f"pairs {key!r} {name}={number}: out of range, must be {allowed}")
            values.append((str(name), float(number)))
        parsed[pair] = tuple(values)  # type: ignore[index]
    return tuple(parsed.items())


@dataclass(frozen=True)
class MaterialTable:
    """Per-type properties (``per_type[key]``, shape (n,)) and per-pair matrices
    (``pairs[key]``, shape (n, n), symmetric) of the ``n`` material types."""

    #: ``species 1``, ..., ``mesh drum``: what each type is, for messages and the log.
    names: tuple[str, ...]
    #: 0-based type of each mesh with a material of its own.
    mesh_types: Mapping[str, int]
    per_type: Mapping[str, NDArray[np.float64]]
    pairs: Mapping[str, NDArray[np.float64]]
    #: The (i, j) entries ``DEM(pairs=...)`` set, i <= j.
    given: frozenset[tuple[int, int]]

    @property
    def size(self) -> int:
        return len(self.names)

    def has(self, key: str) -> bool:
        return key in self.per_type or key in self.pairs

    def describe(self) -> str:
        """The pair matrices as a small text table (one row per pair, ``*`` for a given value)."""
        keys = list(self.pairs)
        rows = [["pair", *keys]]
        for i in range(self.size):
            for j in range(i, self.size):
                mark = "*" if (i, j) in self.given else ""
                rows.append(
                    [
                        f"{self.names[i]} - {self.names[j]}{mark}",
                        *(f"{self.pairs[k][i, j]:.6g}" for k in keys),
                    ]
                )
        widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
        lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]
        return "material pairs (* given by pairs=, others mixed):\n" + "\n".join(lines)


def build_table(
    species: Sequence[Mapping[str, Any]],
    meshes: Sequence[tuple[str, Mapping[str, Any] | None]],
    pairs: Pairs,
    required: Sequence[str],
) -> MaterialTable:
    """The table of ``species`` materials and ``meshes`` (name, material or None), with the
    ``pairs`` of :func:`parse_pairs` over the mixed values; ``required`` the model's keys."""
    names = [f"species {k}" for k in range(1, len(species) + 1)]
    materials = [dict(m) for m in species]
    mesh_types: dict[str, int] = {}
    for name, material in meshes:
        if material:
            mesh_types[name] = len(materials)
            names.append(f"mesh {name}")
            materials.append(dict(material))
    needed = [k for k in required if k != "radius"]

    def column(key: str) -> NDArray[np.float64] | None:
        unused = key in PAIR_KEYS and key not in DEFAULTS and key not in needed  # another model's key
        if unused or (all(key not in m for m in materials) and key not in needed and key not in DEFAULTS):
            return None
        values = []
        for name, material in zip(names, materials):
            if key in material:
                values.append(float(material[key]))
            elif key in needed:
                raise ConfigError(f"The contact model needs {key!r} in every material: {name} has none")
            else:
                values.append(DEFAULTS[key])
        return np.array(values, float)

    per_type = {key: c for key in TYPE_KEYS if (c := column(key)) is not None}
    matrices: dict[str, NDArray[np.float64]] = {}
    for key, (rule, check, allowed) in PAIR_KEYS.items():
        values = column(key)
        if values is None:
            continue
        bad = [names[i] for i, v in enumerate(values) if not check(v)]
        if bad:
            raise ConfigError(f"{key} of {', '.join(bad)} is out of range: it must be {allowed}")
        matrices[key] = np.asarray(mixing.pair_table(rule, values), np.float64)
    index = {f"species {k}": k - 1 for k in range(1, len(species) + 1)} | {
        f"mesh {m}": t for m, t in mesh_types.items()
    }
    given = set()
    for (a, b), values_given in pairs:
        i, j = sorted(index[f"species {x}" if isinstance(x, int) else f"mesh {x}"] for x in (a, b))
        given.add((i, j))
        for key, number in values_given:
            if key not in matrices:
                raise ConfigError(f"pairs ({a!r}, {b!r}) sets {key}, which the contact model does not use")
            matrices[key][i, j] = matrices[key][j, i] = number
    return MaterialTable(tuple(names), mesh_types, per_type, matrices, frozenset(given))
