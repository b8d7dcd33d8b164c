"""The XDMF sidecar of an H5MD trajectory, for ParaView (and VTK, meshio): ``traj.xdmf`` and
its data ``traj.xdmf.h5`` next to ``traj.h5md``, written frame by frame with it.

ParaView has no H5MD reader, and XDMF readers cannot take one frame out of H5MD's
(frames, rows) arrays, whose rows keep each particle's identity and leave gaps where particles
have gone. So each frame's particles are stored again, as they were written, in the sidecar's
data file (``/frames/<k>/<j>``, the j-th column group of frame k), and ``traj.xdmf`` lists one
uniform grid per frame in a temporal collection (XDMF 3): the particles as points (a
``Polyvertex`` topology), their ``Time`` the simulated time of the frame (its step when the
frame has none), and every column as point data: ``position``, ``velocity``, ``force``,
``angular_velocity`` and ``torque`` as vectors, ``id``, ``type``, ``radius`` and any other
column as scalars. ``position`` is point data too, for readers (meshio's time series) that take
the points of the first frame only.

The XML is appended to frame by frame, so ParaView opens a running simulation's sidecar; the
data file is closed after each frame, so a killed writer leaves every earlier frame readable.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from pygran_core.formats.hdf5 import Claim, WriteError, no_space

_HEAD = (
    '<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n <Domain>\n'
    '  <Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
)
_TAIL = "  </Grid>\n </Domain>\n</Xdmf>\n"


def sidecar_paths(trajectory: Path) -> tuple[Path, Path]:
    """The XDMF file and its data file for the H5MD file ``trajectory``."""
    xdmf = trajectory.with_suffix(".xdmf")
    return xdmf, xdmf.with_name(xdmf.name + ".h5")


def _item(data: np.ndarray, where: str) -> str:
    kind, precision = ("Int", 8) if data.dtype.kind in "iub" else ("Float", 8)
    dims = " ".join(str(d) for d in data.shape)
    return (
        f'<DataItem Dimensions="{dims}" NumberType="{kind}" Precision="{precision}" '
        f'Format="HDF">{where}</DataItem>'
    )


class XdmfSidecar:
    """Writes the sidecar of one H5MD trajectory; :meth:`add` appends a frame."""

    def __init__(self, trajectory: Path, compression: int = 4) -> None:
        import h5py

        self.xdmf, self.data = sidecar_paths(trajectory)
        self.compression = compression
        self._claims = [Claim(self.xdmf), Claim(self.data)]
        for claim in self._claims:
            claim.truncate()
        try:
            h5py.File(self.data, "w").close()
        except (OSError, RuntimeError) as exc:
            raise WriteError(f"{self.data}: cannot be created: {exc}") from None
        self._write_xml(_HEAD + _TAIL, at_end=False)
        self._connectivity: tuple[int, str] | None = None

    def add(self, index: int, time: float, groups: Sequence[tuple[str, np.ndarray]]) -> None:
        """Frame ``index`` at ``time``: ``groups`` are (name, (n,) or (n, 3) array), the first
        one the positions."""
        import h5py

        n = len(groups[0][1])
        self._claims[1].reserve(sum(a.nbytes for _, a in groups) + 8 * n)
        items: list[tuple[str, np.ndarray, str]] = []
        try:
            with h5py.File(self.data, "a") as f:
                frame = f.require_group(f"frames/{index}")
                packed = {"compression": "gzip", "compression_opts": self.compression, "shuffle": True}
                for j, (name, values) in enumerate(groups):
                    frame.create_dataset(str(j), data=values, **(packed if n and self.compression else {}))
                    items.append((name, values, f"{self.data.name}:/frames/{index}/{j}"))
                if self._connectivity is None or self._connectivity[0] != n:
                    frame.create_dataset("vertices", data=np.arange(n, dtype=np.int64))
                    self._connectivity = (n, f"{self.data.name}:/frames/{index}/vertices")
        except (OSError, RuntimeError) as exc:
            why = "no space left" if no_space(exc) else str(exc)
            raise WriteError(f"{self.data}: frame {index} could not be written: {why}") from None
        vertices = np.empty(n, dtype=np.int64)
        lines = [
            f'   <Grid Name="frame {index}" GridType="Uniform">',
            f'    <Time Value="{time!r}"/>',
            f'    <Topology TopologyType="Polyvertex" NumberOfElements="{n}" NodesPerElement="1">'
            f"{_item(vertices, self._connectivity[1])}</Topology>",
            f'    <Geometry GeometryType="XYZ">{_item(items[0][1], items[0][2])}</Geometry>',
        ]
        for name, values, where in items:
            kind = "Vector" if values.ndim == 2 else "Scalar"
            lines.append(
                f'    <Attribute Name={quoteattr(name)} AttributeType="{kind}" Center="Node">'
                f"{_item(values, where)}</Attribute>"
            )
        lines.append("   </Grid>\n")
        self._write_xml("\n".join(lines) + _TAIL, at_end=True)

    def _write_xml(self, text: str, at_end: bool) -> None:
        """Write ``text`` over the closing tags (``at_end``) or as the whole file."""
        encoded = text.encode()
        self._claims[0].reserve(len(encoded))
        try:
            with open(self.xdmf, "r+b") as handle:
                if at_end:
                    handle.seek(-len(_TAIL), os.SEEK_END)
                handle.write(encoded)
                handle.truncate()
        except OSError as exc:
            raise WriteError(f"{self.xdmf}: could not be written: {exc.strerror}") from None

    def close(self) -> None:
        for claim in self._claims:
            claim.release()


def frame_groups(
    arrays: dict[str, Any], elements: Sequence[tuple[str, tuple[str, ...]]]
) -> list[tuple[str, np.ndarray]]:
    """The sidecar's point data of a frame: ``elements`` (H5MD name, columns), vectors as
    (n, 3) arrays named by their element, other columns as (n,) arrays under their own name;
    positions first."""
    groups = [
        (name, np.column_stack([arrays[c] for c in cols]))
        if len(cols) == 3
        else (cols[0], np.asarray(arrays[cols[0]]))
        for name, cols in elements
    ]
    groups.sort(key=lambda item: item[0] != "position")
    return groups
