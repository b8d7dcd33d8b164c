"""LIGGGHTS' contact records (``traj`` ``cfile``) read back: the files its ``dump local`` of
the computes :data:`~.commands.CONTACT_COMPUTES` writes in :data:`~.commands.CONTACTS_DIR`,
a file per compute and frame, as the columns of PyGran's contact schema.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pygran_core.formats import contacts as contact_schema
from pygran_core.io import open_trajectory
from pygran_liggghts.commands import CONTACT_COMPUTES


def read_contacts(
    folder: Path, walls: Sequence[int], after: int, until: int
) -> list[tuple[int, dict[str, np.ndarray]]]:
    """``(step, records)`` of the frames in ``folder`` of the steps after ``after`` up to
    ``until``, in order: the pairs of ``compute pair/gran/local``, then the mesh-wall contacts
    of ``wall/gran/local`` with ``id2 = -(walls[i] + 1)`` for LIGGGHTS' mesh ``i``. Every file
    is removed: those read, and those of other steps (a run writes them again as it starts)."""
    by_step: dict[int, dict[str, Path]] = {}
    for path in folder.glob("pg_*.*.dump"):
        compute, number = path.name.split(".")[:2]
        by_step.setdefault(int(number), {})[compute] = path
    frames = []
    for step, paths in sorted(by_step.items()):
        if step <= after or step > until:
            for path in paths.values():
                path.unlink()
            continue
        parts = []
        for compute, path in sorted(paths.items()):
            with open_trajectory(path, compute=CONTACT_COMPUTES[compute]) as dump:
                arrays = dump[0].arrays
            if compute == "pg_walls":  # id2 = -(LIGGGHTS' mesh index + 1)
                arrays["id2"] = -(np.array(walls, dtype=np.int64)[-arrays["id2"] - 1] + 1)
            parts.append(arrays)
            path.unlink()
        frames.append(
            (step, {name: np.concatenate([part[name] for part in parts]) for name in contact_schema.COLUMNS})
        )
    return frames
