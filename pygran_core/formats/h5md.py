"""HDF5 trajectories in the H5MD layout (https://www.nongnu.org/h5md/), read and written.

Layout written (``<g>`` is the particle group, ``all`` by default)::

    /h5md                         version = [1, 1]; author/, creator/ with a name attribute
    /particles/<g>/box            dimension = 3, boundary = periodic|none per axis
        edges/{step,time,value}   (F, 3) box lengths (F, 3, 3) box vectors when triclinic
        pygran_bounds/...         (F, 3, 2) the exact dump bounds; pygran_tilt (F, 3) if any
    /particles/<g>/<element>/{step,time,value}
        position, velocity, force, image   (F, N, 3) from x y z, vx vy vz, fx fy fz, ix iy iz
        id (F, N) int, padded with -1; species (F, N) from ``type``; any other column (F, N)
    /observables/<g>/particle_number/{step,time,value}   (F,) particles in each frame

Every ``value`` is chunked, gzip-compressed and resizable in frames and particles; rows
beyond a frame's particle count hold the fill value (-1 for integers, NaN for floats).
``step`` and ``time`` are one pair of datasets hard-linked into every element. The file is
written in SWMR mode and flushed after every frame, so a killed writer leaves every
completed frame readable; ``particle_number`` is written last and sets the frame count.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.io import Frame, PathLike, Trajectory, TrajectoryWriter

#: H5MD vector elements and the dump columns they hold.
VECTORS = {
    "position": ("x", "y", "z"),
    "velocity": ("vx", "vy", "vz"),
    "force": ("fx", "fy", "fz"),
    "image": ("ix", "iy", "iz"),
}
#: H5MD scalar element names that differ from the dump column.
RENAMED = {"type": "species"}
SI_UNITS = {
    "position": "m",
    "velocity": "m s-1",
    "force": "kg m s-2",
    "radius": "m",
    "diameter": "m",
    "mass": "kg",
    "density": "kg m-3",
    "time": "s",
}
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_PARTICLE_CHUNK = 65536


def can_open(path: Path) -> bool:
    """True for an HDF5 file (H5MD or not: the reader says what is missing)."""
    try:
        with open(path, "rb") as handle:
            return handle.read(8) == HDF5_SIGNATURE
    except OSError:
        return False


def _elements(columns: Sequence[str]) -> list[tuple[str, tuple[str, ...]]]:
    """Group frame columns into H5MD elements, in the order of their first column."""
    elements: list[tuple[str, tuple[str, ...]]] = []
    taken: set[str] = set()
    for name in columns:
        if name in taken:
            continue
        vector = next(
            (e for e, cols in VECTORS.items() if name in cols and all(c in columns for c in cols)), None
        )
        if vector is not None:
            elements.append((vector, VECTORS[vector]))
            taken.update(VECTORS[vector])
        else:
            elements.append((RENAMED.get(name, name), (name,)))
            taken.add(name)
    return elements


class H5MDWriter(TrajectoryWriter):
    """Appends particle frames to an H5MD file, flushing each one.

    Options: ``group`` (particle group name), ``units`` (``"si"`` or a mapping from element
    name to unit string, written as ``unit`` attributes), ``compression`` level (gzip 0-9).
    """

    def __init__(
        self,
        path: PathLike,
        group: str = "all",
        units: str | dict[str, str] | None = None,
        compression: int = 4,
    ) -> None:
        if isinstance(units, str) and units != "si":
            raise UnsupportedFeature(f"H5MD units must be 'si' or a mapping, got {units!r}")
        self.path = Path(path)
        self.group = group
        self.units = SI_UNITS if units == "si" else dict(units or {})
        self.compression = compression
        self.count = 0
        self._file: Any = None
        self._columns: list[str] | None = None
        self._boundary: tuple[str, ...] | None = None
        self._pending: list[Frame] = []

    # -- file creation ---------------------------------------------------------------------
    def _create(self, frame: Frame) -> None:
        import h5py

        columns = list(frame.arrays)
        bad = [c for c in columns if np.ndim(frame.arrays[c]) != 1]
        if bad:
            raise UnsupportedFeature(f"H5MD particle columns must be 1-D; {bad} are not (a mesh frame?)")
        n = len(frame.arrays[columns[0]])
        self._file = f = h5py.File(self.path, "w", libver="latest", track_order=True)
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array([1, 1], dtype=np.int32)
        h5md.create_group("author").attrs["name"] = "PyGran"
        creator = h5md.create_group("creator")
        creator.attrs["name"] = "PyGran"
        creator.attrs["version"] = version("pygran-core")
        particles = f.create_group(f"particles/{self.group}", track_order=True)
        self._clock: Any = None  # the element holding the step and time datasets
        self._values: list[tuple[Any, tuple[str, ...]]] = []
        for element, cols in _elements(columns):
            dtype = np.int64 if np.asarray(frame.arrays[cols[0]]).dtype.kind in "iub" else np.float64
            fill = -1 if dtype is np.int64 else np.nan
            tail = (3,) if len(cols) == 3 else ()
            group = self._element(particles, element, (0, n, *tail), dtype, fill)
            self._values.append((group["value"], cols))
        box = particles.create_group("box")
        box.attrs["dimension"] = 3
        self._boundary = frame.boundary
        if frame.boundary is not None:
            box.attrs["boundary"] = np.array(
                ["periodic" if b.startswith("p") else "none" for b in frame.boundary],
                dtype=h5py.string_dtype(),
            )
            box.attrs["pygran_boundary"] = " ".join(frame.boundary)
        self._triclinic = "tilt" in frame.attrs
        self._edges = self._element(
            box, "edges", (0, 3, 3) if self._triclinic else (0, 3), np.float64, np.nan
        )["value"]
        self._bounds = self._element(box, "pygran_bounds", (0, 3, 2), np.float64, np.nan)["value"]
        self._tilt = (
            self._element(box, "pygran_tilt", (0, 3), np.float64, np.nan)["value"]
            if self._triclinic
            else None
        )
        self._number = self._element(
            f.create_group(f"observables/{self.group}"), "particle_number", (0,), np.int64, -1
        )["value"]
        self._columns = columns
        f.swmr_mode = True

    def _element(self, parent: Any, name: str, shape: tuple[int, ...], dtype: Any, fill: Any) -> Any:
        group = parent.create_group(name)
        if self._clock is None:
            self._clock = group
            group.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(1024,))
            group.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(1024,))
            if "time" in self.units:
                group["time"].attrs["unit"] = self.units["time"]
        else:
            group["step"] = self._clock["step"]
            group["time"] = self._clock["time"]
        chunks = (1, *(min(max(s, 1), _PARTICLE_CHUNK) for s in shape[1:2]), *shape[2:])
        value = group.create_dataset(
            "value",
            shape=shape,
            maxshape=(None, *(None for _ in shape[1:2]), *shape[2:]),
            dtype=dtype,
            chunks=chunks,
            fillvalue=fill,
            compression="gzip" if self.compression else None,
            compression_opts=self.compression or None,
            shuffle=bool(self.compression),
        )
        if name in self.units:
            value.attrs["unit"] = self.units[name]
        return group

    # -- appending -----------------------------------------------------------------------------
    def write_frame(self, frame: Frame) -> None:
        if self._file is None:
            if not frame.arrays:
                self._pending.append(frame)  # no columns yet to lay the file out with
                return
            self._create(frame)
            for pending in self._pending:
                self._append(pending)
            self._pending.clear()
        self._append(frame)

    def _append(self, frame: Frame) -> None:
        assert self._columns is not None
        if frame.arrays and list(frame.arrays) != self._columns:
            raise UnsupportedFeature(
                f"H5MD frame {self.count} has columns {list(frame.arrays)}, but the file was laid "
                f"out for {self._columns}; write frames with different columns to separate files"
            )
        if frame.boundary != self._boundary and frame.boundary is not None:
            raise UnsupportedFeature(
                f"H5MD frame {self.count} changes the boundary flags to "
                f"{frame.boundary} from {self._boundary}"
            )
        n = len(next(iter(frame.arrays.values()))) if frame.arrays else 0
        k = self.count
        step = frame.timestep if frame.timestep is not None else k
        for name, value in (("step", step), ("time", np.nan if frame.time is None else frame.time)):
            dataset = self._clock[name]
            dataset.resize((k + 1,))
            dataset[k] = value
        for value, cols in self._values:
            if n > value.shape[1]:
                value.resize(n, axis=1)
            value.resize(k + 1, axis=0)
            if n:
                data = (
                    np.column_stack([frame.arrays[c] for c in cols])
                    if len(cols) == 3
                    else np.asarray(frame.arrays[cols[0]])
                )
                value[k, :n] = data
        box = frame.box if frame.box is not None else np.full((3, 2), np.nan)
        box = np.asarray(box, dtype=np.float64)
        lengths = box[:, 1] - box[:, 0]
        for dataset, data in (
            (self._edges, _edges(lengths, frame.attrs.get("tilt"), self._triclinic)),
            (self._bounds, box),
            (self._tilt, frame.attrs.get("tilt")),
        ):
            if dataset is not None:
                dataset.resize(k + 1, axis=0)
                dataset[k] = data
        self._number.resize((k + 1,))
        self._number[k] = n
        self._file.flush()
        self.count += 1

    def close(self) -> None:
        if self._file is None and self._pending:
            raise UnsupportedFeature("H5MD: no frame with particle columns was written; nothing to lay out")
        if self._file is not None:
            self._file.close()
            self._file = None


def _edges(lengths: np.ndarray, tilt: Any, triclinic: bool) -> np.ndarray:
    if not triclinic:
        return lengths
    xy, xz, yz = np.asarray(tilt, dtype=np.float64)
    return np.array([[lengths[0], 0, 0], [xy, lengths[1], 0], [xz, yz, lengths[2]]])


class H5MDTrajectory(Trajectory):
    """Frames of one H5MD file's particle group (``group=None``: the only one there is)."""

    def __init__(self, paths: Sequence[PathLike], group: str | None = None) -> None:
        import h5py

        if len(paths) != 1:
            raise UnsupportedFeature(f"H5MD reads one file at a time, got {len(paths)}")
        self.path = Path(paths[0])
        try:
            # swmr=True also opens a file whose writer was killed before closing it.
            self._file = h5py.File(self.path, "r", swmr=True)
        except OSError as exc:
            raise ReadError(f"{self.path}: not a readable HDF5 file: {exc}") from exc
        try:
            self._index(group)
        except (KeyError, ValueError, TypeError, OSError) as exc:
            self._file.close()
            raise ReadError(f"{self.path}: not an H5MD particle file: {exc}") from exc

    def _index(self, group: str | None) -> None:
        import h5py

        particles = self._file.get("particles")
        if not isinstance(particles, h5py.Group) or not len(particles):
            raise ReadError(f"{self.path}: no /particles group: not an H5MD trajectory")
        names = list(particles)
        if group is None:
            if len(names) != 1:
                raise ReadError(f"{self.path}: several particle groups {names}; pass group=...")
            group = names[0]
        if group not in particles:
            raise ReadError(f"{self.path}: no particle group {group!r}; the file has {names}")
        self.group = group
        root = particles[group]
        self._elements: list[tuple[str, Any]] = [(name, obj) for name, obj in root.items() if name != "box"]
        lengths = [len(obj["value"]) for _, obj in self._elements if isinstance(obj, h5py.Group)]
        number = self._file.get(f"observables/{group}/particle_number")
        self._number = number["value"] if number is not None else None
        if self._number is not None:
            lengths.append(len(self._number))
        box = root.get("box")
        self._box = box
        self._box_parts = {
            n: box[n]
            for n in ("edges", "pygran_bounds", "pygran_tilt")
            if box is not None and isinstance(box.get(n), h5py.Group)
        }
        lengths += [len(g["value"]) for g in self._box_parts.values()]
        clock = next((obj for _, obj in self._elements if isinstance(obj, h5py.Group)), None)
        if clock is None:
            raise ReadError(f"{self.path}: particle group {group!r} has no time-dependent element")
        self._step, self._time = clock["step"], clock["time"]
        lengths += [len(self._step), len(self._time)]
        self._n = min(lengths)
        self._boundary: tuple[str, ...] | None = None
        if box is not None and "pygran_boundary" in box.attrs:
            self._boundary = tuple(str(box.attrs["pygran_boundary"]).split())
        elif box is not None and "boundary" in box.attrs:
            flags = [b.decode() if isinstance(b, bytes) else str(b) for b in box.attrs["boundary"]]
            self._boundary = tuple("pp" if b == "periodic" else "ff" for b in flags)

    @property
    def n_frames(self) -> int:
        return self._n

    def close(self) -> None:
        self._file.close()

    def _read_frame(self, index: int) -> Frame:
        try:
            return self._frame(index)
        except (KeyError, ValueError, TypeError, OSError) as exc:
            raise ReadError(f"{self.path}: frame {index}: {exc}") from exc

    def _frame(self, index: int) -> Frame:
        import h5py

        count = int(self._number[index]) if self._number is not None else None
        arrays: dict[str, np.ndarray] = {}
        for name, obj in self._elements:
            dataset = obj["value"] if isinstance(obj, h5py.Group) else obj
            data = dataset[index] if isinstance(obj, h5py.Group) else dataset[()]
            if count is None and name == "id":
                count = int(np.count_nonzero(data >= 0))
            data = data[:count] if count is not None else data
            if name in VECTORS and data.ndim == 2 and data.shape[1] == 3:
                for j, column in enumerate(VECTORS[name]):
                    arrays[column] = np.ascontiguousarray(data[:, j])
            elif data.ndim == 2:
                for j in range(data.shape[1]):
                    arrays[f"{name}[{j + 1}]"] = np.ascontiguousarray(data[:, j])
            else:
                arrays["type" if name == "species" else name] = data
        if count is not None:
            arrays = {k: v[:count] for k, v in arrays.items()}
        box, attrs = None, {}
        if "pygran_bounds" in self._box_parts:
            box = self._box_parts["pygran_bounds"]["value"][index]
        elif "edges" in self._box_parts:
            edges = self._box_parts["edges"]["value"][index]
            lengths = np.diag(edges) if edges.ndim == 2 else edges
            box = np.column_stack([np.zeros(3), lengths])
        if box is not None and np.isnan(box).all():
            box = None
        if "pygran_tilt" in self._box_parts:
            attrs["tilt"] = self._box_parts["pygran_tilt"]["value"][index]
        time = float(self._time[index])
        return Frame(
            arrays,
            timestep=int(self._step[index]),
            time=None if np.isnan(time) else time,
            box=box,
            boundary=self._boundary,
            attrs=attrs,
        )
