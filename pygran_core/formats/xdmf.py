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
data file is closed after each frame, so a killed writer leaves every earlier frame readable,
and opened without HDF5's own file lock (the writer holds a :class:`~pygran_core.formats.hdf5.Claim`),
so a viewer that keeps it open does not stop the writer.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.etree import ElementTree
from xml.sax.saxutils import quoteattr

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature, WriteError
from pygran_core.formats.base import Frame, PathLike, Trajectory
from pygran_core.formats.hdf5 import Claim, load_h5py, no_space, open_hdf5
from pygran_core.formats.sanity import particle_problem, step_problem

_HEAD = (
    '<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n <Domain>\n'
    '  <Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n'
)
_TAIL = "  </Grid>\n </Domain>\n</Xdmf>\n"
#: The vector elements of H5MD (and point data of the sidecar) and the LIGGGHTS columns they hold.
VECTORS = {
    "position": ("x", "y", "z"),
    "velocity": ("vx", "vy", "vz"),
    "force": ("fx", "fy", "fz"),
    "image": ("ix", "iy", "iz"),
    "angular_velocity": ("omegax", "omegay", "omegaz"),
    "torque": ("tqx", "tqy", "tqz"),
}


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
        h5py = load_h5py()

        self.xdmf, self.data = sidecar_paths(trajectory)
        self.compression = compression
        self._claims = [Claim(self.xdmf), Claim(self.data)]
        for claim in self._claims:
            claim.truncate()
        try:
            h5py.File(self.data, "w", locking=False).close()
        except (OSError, RuntimeError) as exc:
            raise WriteError(f"{self.data}: cannot be created: {exc}") from None
        self._write_xml(_HEAD + _TAIL, at_end=False)
        self._connectivity: tuple[int, str] | None = None

    def add(
        self,
        index: int,
        step: int,
        time: float,
        arrays: dict[str, Any],
        elements: Sequence[tuple[str, tuple[str, ...]]],
    ) -> None:
        """Frame ``index`` of ``step`` at ``time``: the columns ``arrays`` grouped as ``elements``
        (H5MD name, columns; ``position`` among them), vectors stored as (n, 3) arrays named by
        their element, other columns as (n,) arrays under their own name; one group is in
        memory at a time."""
        h5py = load_h5py()

        n = len(arrays[dict(elements)["position"][0]])
        self._claims[1].reserve(
            sum(np.asarray(arrays[c]).nbytes for _, cols in elements for c in cols) + 8 * n
        )
        items: list[tuple[str, str, bool]] = []  # name, data item, vector
        geometry = ""
        try:
            with h5py.File(self.data, "a", locking=False) as f:
                frame = f.require_group(f"frames/{index}")
                packed = {"compression": "gzip", "compression_opts": self.compression, "shuffle": True}
                for j, (name, cols) in enumerate(elements):
                    values = stacked([arrays[c] for c in cols])
                    frame.create_dataset(str(j), data=values, **(packed if n and self.compression else {}))
                    item = _item(values, f"{self.data.name}:/frames/{index}/{j}")
                    vector = len(cols) == 3
                    items.append((name if vector else cols[0], item, vector))
                    geometry = item if name == "position" else geometry
                    del values  # before the next group is stacked
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
            f'    <Information Name="step" Value="{step}"/>',
            f'    <Topology TopologyType="Polyvertex" NumberOfElements="{n}" NodesPerElement="1">'
            f"{_item(vertices, self._connectivity[1])}</Topology>",
            f'    <Geometry GeometryType="XYZ">{geometry}</Geometry>',
        ]
        for name, item, vector in items:
            lines.append(
                f'    <Attribute Name={quoteattr(name)} AttributeType="{"Vector" if vector else "Scalar"}" '
                f'Center="Node">{item}</Attribute>'
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
            claim.close()


def interleaved(columns: Sequence[np.ndarray]) -> np.ndarray | None:
    """The (n, k) C-contiguous array whose columns ``columns`` are (as an engine's frame
    gives x y z: the columns of one (n, 3) array), or None when they are not."""
    first = columns[0]
    if not all(isinstance(c, np.ndarray) and c.ndim == 1 for c in columns):
        return None
    size, start = first.dtype.itemsize, first.__array_interface__["data"][0]
    for j, column in enumerate(columns):
        if (
            column.dtype != first.dtype
            or column.shape != first.shape
            or column.strides != (len(columns) * size,)
            or column.__array_interface__["data"][0] != start + j * size
        ):
            return None
    shape = (len(first), len(columns))
    return np.lib.stride_tricks.as_strided(first, shape, (len(columns) * size, size), writeable=False)


def stacked(columns: Sequence[Any]) -> np.ndarray:
    """One column as an array, or several as the (n, k) array of them (copied only when they
    are not already the columns of one)."""
    if len(columns) == 1:
        return np.asarray(columns[0])
    whole = interleaved(columns)
    return np.column_stack(columns) if whole is None else whole


class XdmfTrajectory(Trajectory):
    """The particle frames of an XDMF sidecar this module wrote, read back: one frame per grid,
    its columns from the point data, its time and step from the grid.

    Only data in a plain file next to the XDMF file is read (an HDF5 file opened as every HDF5
    file is, refusing one that reaches outside itself); anything else is a :class:`ReadError`.
    """

    def __init__(self, paths: Sequence[PathLike]) -> None:
        if len(paths) != 1:
            raise UnsupportedFeature(f"XDMF reads one file at a time, got {len(paths)}")
        self.path = Path(paths[0])
        try:
            root = ElementTree.parse(self.path).getroot()
        except (ElementTree.ParseError, OSError) as exc:
            raise ReadError(f"{self.path}: not a readable XDMF file: {exc}") from None
        self._grids = [g for g in root.iter("Grid") if g.get("GridType") == "Uniform"]
        if root.tag != "Xdmf" or root.find("Domain/Grid[@CollectionType='Temporal']") is None:
            raise ReadError(f"{self.path}: not an XDMF time series (no temporal collection of grids)")
        self._data: Any = None

    @property
    def n_frames(self) -> int:
        return len(self._grids)

    def _dataset(self, item: ElementTree.Element | None) -> np.ndarray:
        if item is None or item.get("Format") != "HDF" or ":" not in (item.text or ""):
            raise ReadError(f"{self.path}: a data item that is not HDF5 data (file:/path)")
        name, where = (item.text or "").strip().split(":", 1)
        if Path(name).name != name or name in ("", ".", ".."):
            raise ReadError(f"{self.path}: data in {name!r}: only a file next to the XDMF file is read")
        if self._data is None:
            self._data = open_hdf5(self.path.parent / name)
        try:
            values = np.asarray(self._data[where][()])
        except (KeyError, OSError, RuntimeError, ValueError, TypeError) as exc:
            raise ReadError(f"{self.path}: data {where!r}: {exc}") from None
        if values.dtype.kind not in "biuf" or values.ndim not in (1, 2):
            raise ReadError(f"{self.path}: data {where!r} has shape {values.shape} and type {values.dtype}")
        return values

    def _read_frame(self, index: int) -> Frame:
        grid = self._grids[index]
        arrays: dict[str, np.ndarray] = {}
        for attribute in grid.iter("Attribute"):
            name, values = attribute.get("Name", ""), self._dataset(attribute.find("DataItem"))
            values = values.astype(np.int64 if values.dtype.kind in "biu" else np.float64)
            if values.ndim == 2 and name in VECTORS and values.shape[1] == 3:
                arrays.update({c: np.ascontiguousarray(values[:, j]) for j, c in enumerate(VECTORS[name])})
            elif values.ndim == 1:
                arrays[name] = values
            else:
                raise ReadError(f"{self.path}: frame {index}: point data {name!r} has shape {values.shape}")
        if len({len(v) for v in arrays.values()}) > 1:
            raise ReadError(f"{self.path}: frame {index}: the point data hold different particle counts")
        problem = particle_problem(arrays)
        if problem:
            raise ReadError(f"{self.path}: frame {index}: {problem}")
        try:
            time = float(grid.find("Time").get("Value", ""))  # type: ignore[union-attr]
            step = grid.find("Information[@Name='step']")
            timestep = None if step is None else int(step.get("Value", ""))
        except (AttributeError, ValueError) as exc:
            raise ReadError(f"{self.path}: frame {index}: no readable time or step ({exc})") from None
        if index and timestep is not None:
            previous = self._grids[index - 1].find("Information[@Name='step']")
            problem = step_problem(int(previous.get("Value", "")) if previous is not None else None, timestep)
            if problem:
                raise ReadError(f"{self.path}: frame {index}: {problem}")
        return Frame(arrays, timestep=timestep, time=time)

    def close(self) -> None:
        if self._data is not None:
            self._data.close()
            self._data = None
