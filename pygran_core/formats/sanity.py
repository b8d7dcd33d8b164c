"""The physical sanity every particle frame must have, whoever wrote it: the one place readers
and writers take it from.

A file can be well-formed and still lie: two particles with one id, a radius of zero, a mass
below zero, steps that run backwards. Such a frame is refused (a reader raises
:class:`~pygran_core.errors.ReadError`, a writer refuses to write it) rather than handed to an
analysis that would divide by the radius or match particles by id.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

#: Columns that must be positive wherever they are given.
POSITIVE = ("radius", "diameter", "mass", "density")


def particle_problem(arrays: Mapping[str, np.ndarray]) -> str | None:
    """What is physically wrong with one frame's particle columns, or None."""
    ids = arrays.get("id")
    if ids is not None and len(ids) and not _distinct(np.asarray(ids)):
        unique, counts = np.unique(ids, return_counts=True)
        repeated = unique[counts > 1]
        return f"{len(repeated)} ids appear more than once (such as {int(repeated[0])})"
    for name in POSITIVE:
        values = arrays.get(name)
        if values is not None and len(values):
            bad = ~(np.asarray(values) > 0)
            if bad.any():
                example = float(np.asarray(values)[bad][0])
                return f"{int(bad.sum())} particles have a {name} that is not positive (such as {example!r})"
    return None


def _distinct(ids: np.ndarray) -> bool:
    """Whether no value of ``ids`` repeats: ids numbered from 0 or 1 (as engines give them) are
    marked in a table, in one pass; other values are sorted."""
    if ids.dtype.kind in "iu" and 0 <= ids.min() and ids.max() < 4 * len(ids) + 1024:
        seen = np.zeros(int(ids.max()) + 1, dtype=bool)
        seen[ids] = True
        return int(np.count_nonzero(seen)) == len(ids)
    return len(np.unique(ids)) == len(ids)


def step_problem(previous: int | None, step: int) -> str | None:
    """What is wrong with ``step`` following ``previous`` (steps only increase), or None."""
    if previous is not None and step <= previous:
        return f"step {step} follows step {previous}: steps must increase from frame to frame"
    return None
