"""Per-contact records: the schema every engine writes and every reader gives.

A contacts frame is a :class:`~pygran_core.formats.base.Frame` with
``attrs["kind"] == "contacts"`` whose ``arrays`` are exactly :data:`COLUMNS`, one row per
contact, at the timestep of the particle frame it belongs to:

- ``id1``, ``id2`` (int64): the particles in contact. ``id2 < 0`` marks a wall contact:
  ``id2 = -(k + 1)`` for the k-th wall (0-based) the simulation set up (see :func:`wall_id`):
  first the meshes of ``mesh={...}`` that are walls from the start (not ``'import': False``),
  in the order of that dict, then each ``setupWall`` call that makes a wall (one on a mesh
  that is a wall already makes none, unless it makes the wall anew for another species of a
  mesh without material); removed walls keep their numbers and count. Every engine writes this; only a
  ``wall/gran/local`` file LIGGGHTS wrote itself numbers its mesh walls by their place in its
  fix (:func:`from_liggghts`).
- ``fx fy fz``: the force on ``id1`` by ``id2`` (normal plus tangential); ``id2`` feels the
  opposite.
- ``cx cy cz``: the contact point, on the segment from ``id1``'s centre to ``id1``'s centre
  minus the branch vector, so in a periodic box it may lie outside the box by less than a radius;
  a wall's is on the wall's surface.
- ``bx by bz``: the branch vector ``r1 - r2`` with the minimum image across periodic
  boundaries; for a wall, ``r1 - c``.

Rows may name particles absent from a particle frame written at the same step (a particle
selection ``traj sel``, or a frame of another file): readers keep them, and analysis that
needs both matches them by id.

A contacts dump (LIGGGHTS' ``dump local``) holds the pair contacts; the wall contacts go to a
file beside it (:func:`wall_file`: ``contacts.dump`` -> ``wall-contacts.dump``), as LIGGGHTS
writes ``pair/gran/local`` and ``wall/gran/local`` to two dumps. So every row of the pair file
is a bond between two particles, which OVITO loads as such (:data:`OVITO_COLUMNS`), and the
dump reader gives both files' rows as one frame.

LIGGGHTS' ``compute pair/gran/local`` and ``wall/gran/local`` columns, as its ``dump local``
writes them (``c_ID[1] c_ID[2] ...``), are mapped to the schema by :func:`from_liggghts`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

_Index = TypeVar("_Index", int, np.ndarray)

KIND = "contacts"
#: The columns of a contacts frame, in order.
COLUMNS = ("id1", "id2", "fx", "fy", "fz", "cx", "cy", "cz", "bx", "by", "bz")
INT_COLUMNS = frozenset({"id1", "id2"})
#: Column groups as 3-vectors (H5MD elements ``force``, ``point``, ``branch``).
VECTORS = {"force": ("fx", "fy", "fz"), "point": ("cx", "cy", "cz"), "branch": ("bx", "by", "bz")}

#: OVITO's bond properties for the columns of a pair-contacts dump, in order: the ``columns``
#: of ``LoadTrajectoryModifier().source.load(path, columns=...)``, which makes each contact a
#: bond with its force, contact point and branch vector (OVITO guesses no mapping itself).
OVITO_COLUMNS = (
    "Particle Identifiers.1",
    "Particle Identifiers.2",
    *(f"{name}.{k}" for name in ("Force", "Contact Point", "Branch") for k in (1, 2, 3)),
)
#: What the name of a contacts dump's wall-contacts file starts with.
WALL_PREFIX = "wall-"

#: Values per keyword of LIGGGHTS 3.8's ``compute pair/gran/local``, in the order of its
#: columns whatever the order of the keywords (``history``: its width is the rest).
LIGGGHTS_KEYWORDS = {
    "pos": 6,
    "vel": 6,
    "id": 3,
    "force": 3,
    "force_normal": 3,
    "force_tangential": 3,
    "torque": 3,
    "torque_normal": 3,
    "torque_tangential": 3,
    "history": -1,
    "contactArea": 1,
    "delta": 1,
    "heatFlux": 1,
    "contactPoint": 3,
    "ms_id": 2,
}
#: The keywords LIGGGHTS takes when none is given.
LIGGGHTS_DEFAULT = ("pos", "vel", "id", "force", "torque", "history", "contactArea")
_COMPUTE_COLUMN = re.compile(r"^c_([A-Za-z0-9_\-]+)\[(\d+)\]$")


def wall_id(index: _Index) -> _Index:
    """``id2`` of a contact with the ``index``-th wall set up (0-based, see the module's rule;
    an int or an array of them): ``-(index + 1)``."""
    return -(index + 1)


def is_contacts(columns: Sequence[str]) -> bool:
    """Whether ``columns`` are the schema's (in any order)."""
    return sorted(columns) == sorted(COLUMNS)


def empty() -> dict[str, np.ndarray]:
    """The arrays of a frame without contacts."""
    return {name: np.empty(0, np.int64 if name in INT_COLUMNS else np.float64) for name in COLUMNS}


def wall_file(path: Path) -> Path:
    """The file of the wall contacts beside the contacts dump ``path``."""
    return path.with_name(WALL_PREFIX + path.name)


def split(arrays: Mapping[str, np.ndarray]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The rows of particle pairs and those of walls (``id2 < 0``), each in the schema's order."""
    wall = np.asarray(arrays["id2"]) < 0
    return (
        {name: np.asarray(arrays[name])[~wall] for name in COLUMNS},
        {name: np.asarray(arrays[name])[wall] for name in COLUMNS},
    )


def checked(arrays: Mapping[str, Any], where: str) -> dict[str, np.ndarray]:
    """``arrays`` as the schema's columns in order, int64/float64, one length; else a
    :class:`ValueError` naming ``where`` and the problem."""
    missing = [c for c in COLUMNS if c not in arrays]
    extra = [c for c in arrays if c not in COLUMNS]
    if missing or extra:
        raise ValueError(
            f"{where}: contact columns must be {list(COLUMNS)}; missing {missing}, unknown {extra}"
        )
    out = {}
    for name in COLUMNS:
        value = np.asarray(arrays[name])
        if value.ndim != 1:
            raise ValueError(f"{where}: contact column {name!r} has shape {value.shape}, not (n,)")
        out[name] = value.astype(np.int64 if name in INT_COLUMNS else np.float64, copy=False)
    lengths = {len(v) for v in out.values()}
    if len(lengths) > 1:
        raise ValueError(f"{where}: contact columns have different lengths {sorted(lengths)}")
    return out


def minimum_image(delta: np.ndarray, box: np.ndarray | None, boundary: Sequence[str] | None) -> np.ndarray:
    """``delta`` (n, 3) with the periodic axes of ``box`` folded to the nearest image."""
    if box is None or boundary is None:
        return delta
    out = np.array(delta, dtype=np.float64)
    for axis, flag in enumerate(boundary):
        if flag.startswith("p"):
            length = float(box[axis][1] - box[axis][0])
            out[:, axis] -= length * np.round(out[:, axis] / length)
    return out


def _layout(compute: str, width: int) -> tuple[bool, dict[str, int]]:
    """Whether ``compute`` (``"pair/gran/local pos id ..."``) is a wall compute, and the
    0-based column where each of its keywords starts, for ``width`` columns in all."""
    words = compute.split()
    if not words or words[0] not in ("pair/gran/local", "wall/gran/local"):
        raise ValueError(
            f"compute={compute!r}: give the style and keywords of LIGGGHTS' compute, such as "
            "'pair/gran/local pos id force contactPoint' or 'wall/gran/local pos id force'"
        )
    keywords = words[1:] or list(LIGGGHTS_DEFAULT)
    unknown = [k for k in keywords if k not in LIGGGHTS_KEYWORDS]
    if unknown:
        raise ValueError(f"compute={compute!r}: unknown keywords {unknown}; known: {list(LIGGGHTS_KEYWORDS)}")
    fixed = sum(LIGGGHTS_KEYWORDS[k] for k in set(keywords) if k != "history")
    starts, column = {}, 0
    for keyword, size in LIGGGHTS_KEYWORDS.items():
        if keyword in keywords:
            starts[keyword] = column
            column += width - fixed if size < 0 else size
    return words[0] == "wall/gran/local", starts


def from_liggghts(
    columns: Sequence[str],
    table: Mapping[str, np.ndarray],
    compute: str,
    box: np.ndarray | None,
    boundary: Sequence[str] | None,
) -> dict[str, np.ndarray]:
    """The schema's arrays from the ``c_ID[k]`` columns of one LIGGGHTS ``compute`` (its style
    and keywords, as in the input script). Needs ``id``, ``force`` (or ``force_normal`` and
    ``force_tangential``), ``pos`` and, for particle pairs, ``contactPoint``; the branch
    vector of a pair is the minimum image of ``pos`` (which LIGGGHTS wraps into the box).
    A :class:`ValueError` says what is missing."""
    found = [_COMPUTE_COLUMN.match(c) for c in columns]
    ids = {m.group(1) for m in found if m}
    if len(ids) != 1 or not all(found):
        raise ValueError(
            f"compute={compute!r} maps the columns c_ID[1] c_ID[2] ... of one compute, but the "
            f"file has {list(columns)}"
        )
    by_index = {int(m.group(2)) - 1: table[c] for m, c in zip(found, columns) if m}
    wall, starts = _layout(compute, max(by_index) + 1)

    def block(keyword: str, size: int) -> np.ndarray:
        if keyword not in starts:
            raise ValueError(f"compute={compute!r} has no {keyword!r} keyword, which contacts need")
        first = starts[keyword]
        missing = [first + j + 1 for j in range(size) if first + j not in by_index]
        if missing:
            raise ValueError(f"the file lacks the columns {missing} of {keyword!r} (compute={compute!r})")
        return np.column_stack([by_index[first + j] for j in range(size)])

    if "force" in starts:
        force = block("force", 3)
    else:
        force = block("force_normal", 3) + block("force_tangential", 3)
    pos, id_block = block("pos", 6), block("id", 3)
    if wall:  # ids: mesh, triangle, particle; pos: contact point, particle
        id1, id2 = id_block[:, 2], -(id_block[:, 0] + 1)
        point = pos[:, :3]
        branch = pos[:, 3:] - point
    else:
        id1, id2 = id_block[:, 0], id_block[:, 1]
        point = block("contactPoint", 3)
        branch = minimum_image(pos[:, :3] - pos[:, 3:], box, boundary)
    arrays: dict[str, np.ndarray] = {"id1": id1, "id2": id2}
    for values, names in ((force, VECTORS["force"]), (point, VECTORS["point"]), (branch, VECTORS["branch"])):
        arrays.update({name: np.ascontiguousarray(values[:, j]) for j, name in enumerate(names)})
    for name in INT_COLUMNS:
        as_int = np.rint(arrays[name]).astype(np.int64)
        if not np.array_equal(as_int, arrays[name]):
            raise ValueError(f"the ids of compute={compute!r} are not integers")
        arrays[name] = as_int
    return arrays
