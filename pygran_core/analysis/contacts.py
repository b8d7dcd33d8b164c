"""Contacts: the per-contact records of one frame as a SubSystem (one element per contact).

Its arrays are the schema of :mod:`pygran_core.formats.contacts`: ``id1``, ``id2`` (``id2 < 0``:
a wall), ``fx fy fz`` (the force on ``id1`` by ``id2``), ``cx cy cz`` (the contact point) and
``bx by bz`` (the branch vector ``r1 - r2`` at minimum image; ``r1 - c`` for a wall).
``System(Particles='traj.h5')`` finds the contacts an H5MD file holds;
``System(Particles='traj*.dump', Contacts='contacts*.dump')`` reads them from their own files.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from pygran_core.analysis.subsystem import DIMENSIONS, SubSystem
from pygran_core.errors import ConfigError
from pygran_core.formats import contacts as _schema


class Contacts(SubSystem):
    """Contact records: ``Contacts(id1=..., id2=..., fx=..., ..., bz=...)`` or from a frame."""

    coordinate_keys = ("cx", "cy", "cz")
    dimensions: Mapping[str, str] = {
        **DIMENSIONS,
        **dict.fromkeys(("cx", "cy", "cz", "bx", "by", "bz"), "length"),
    }

    @classmethod
    def _frame_kwargs(cls, frame: Any) -> dict[str, Any]:
        if frame.attrs.get("kind") != _schema.KIND:
            raise ConfigError(
                f"Not a contacts frame (its arrays are {sorted(frame.arrays)}): give Contacts= a dump local "
                "file of contact records or an H5MD file with a /contacts group"
            )
        return super()._frame_kwargs(frame)

    def _to_frame(self) -> Any:
        frame = super()._to_frame()
        frame.attrs["kind"] = _schema.KIND
        return frame

    @property
    def walls(self) -> np.ndarray:
        """A mask of the contacts with walls (``id2 < 0``)."""
        return np.asarray(self.id2) < 0
