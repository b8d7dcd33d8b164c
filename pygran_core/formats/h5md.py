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

Contact records (:mod:`~pygran_core.formats.contacts`), when written, in the same layout::

    /contacts/<g>/{id1,id2}/{step,time,value}             (F, C) int, padded with 0
    /contacts/<g>/{force,point,branch}/{step,time,value}  (F, C, 3) fx fy fz, cx cy cz, bx by bz
    /observables/<g>/contact_number/{step,time,value}     (F,) contacts in each frame

Every ``value`` is chunked, gzip-compressed and resizable in frames and rows; rows beyond a
frame's count hold the fill value (-1 for particle ids, 0 for contact ids, NaN for floats);
HDF5 stores no chunk that holds fill values only. ``step`` and ``time`` are one pair of
datasets hard-linked into every element of a group (particles, contacts). The file is
written in SWMR mode and flushed after every frame, so a killed writer leaves every
completed frame readable; ``particle_number`` and ``contact_number`` are written last and
set the frame counts.
"""

from __future__ import annotations

import ctypes
import functools
import os
from collections.abc import Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from pygran_core.errors import ReadError, UnsupportedFeature
from pygran_core.formats import contacts as _contacts
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter

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
#: Metadata read attempts of an SWMR reader: HDF5 sleeps 1, 2, 4, ... ns between them, so
#: 20 bound the wait to about a millisecond (its default of 100 is forever).
SWMR_READ_ATTEMPTS = 20
#: What h5py raises on a damaged file (HDF5's own errors are OSError, RuntimeError, KeyError
#: or ValueError; an object of the wrong kind gives TypeError or IndexError).
_DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError)
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
    """Appends particle frames, and contacts frames, to an H5MD file, flushing each one.

    Options: ``group`` (particle group name), ``units`` (``"si"`` or a mapping from element
    name to unit string, written as ``unit`` attributes), ``compression`` level (gzip 0-9),
    ``contacts``: whether contacts frames (``attrs["kind"] == "contacts"``) come besides the
    particle frames (the file is laid out for both at its first particle frame with columns).
    A writer whose first frame is a contacts frame, without ``contacts=True``, writes a file
    of contacts only.
    """

    def __init__(
        self,
        path: PathLike,
        group: str = "all",
        units: str | dict[str, str] | None = None,
        compression: int = 4,
        contacts: bool = False,
    ) -> None:
        if isinstance(units, str) and units != "si":
            raise UnsupportedFeature(f"H5MD units must be 'si' or a mapping, got {units!r}")
        self.path = Path(path)
        self.group = group
        self.units = SI_UNITS if isinstance(units, str) else dict(units or {})
        self.compression = compression
        self.contacts = contacts
        self.count = 0
        self.contact_count = 0
        self._file: Any = None
        self._columns: list[str] | None = None
        self._boundary: tuple[str, ...] | None = None
        self._pending: list[Frame] = []
        self._contact_values: list[tuple[Any, tuple[str, ...]]] = []

    # -- file creation ---------------------------------------------------------------------
    def _create(self, frame: Frame | None) -> None:
        """The file, laid out for the particle frame ``frame`` (None: contacts only) and, if
        asked or if ``frame`` is None, for contacts; then in SWMR mode."""
        import h5py

        self._file = f = h5py.File(self.path, "w", libver="latest", track_order=True)
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array([1, 1], dtype=np.int32)
        h5md.create_group("author").attrs["name"] = "PyGran"
        creator = h5md.create_group("creator")
        creator.attrs["name"] = "PyGran"
        creator.attrs["version"] = version("pygran-core")
        if frame is not None:
            self._layout_particles(f, frame)
        if self.contacts or frame is None:
            self._layout_contacts(f)
        f.swmr_mode = True

    def _layout_contacts(self, f: Any) -> None:
        root = f.create_group(f"contacts/{self.group}", track_order=True)
        clock: Any = None
        for name in ("id1", "id2"):
            group = self._element(root, name, (0, 1), np.int64, 0, clock)
            clock = group if clock is None else clock
            self._contact_values.append((group["value"], (name,)))
        for name, cols in _contacts.VECTORS.items():
            group = self._element(root, name, (0, 1, 3), np.float64, np.nan, clock)
            self._contact_values.append((group["value"], cols))
        self._contact_clock = clock
        observables = f.require_group(f"observables/{self.group}")
        self._contact_number = self._element(observables, "contact_number", (0,), np.int64, -1, clock)[
            "value"
        ]

    def _layout_particles(self, f: Any, frame: Frame) -> None:
        import h5py

        columns = list(frame.arrays)
        bad = [c for c in columns if np.ndim(frame.arrays[c]) != 1]
        if bad:
            raise UnsupportedFeature(f"H5MD particle columns must be 1-D; {bad} are not (a mesh frame?)")
        n = len(frame.arrays[columns[0]])
        particles = f.create_group(f"particles/{self.group}", track_order=True)
        self._clock: Any = None  # the element holding the step and time datasets
        self._values: list[tuple[Any, tuple[str, ...]]] = []
        for element, cols in _elements(columns):
            dtype = np.int64 if np.asarray(frame.arrays[cols[0]]).dtype.kind in "iub" else np.float64
            fill = -1 if dtype is np.int64 else np.nan
            tail = (3,) if len(cols) == 3 else ()
            group = self._element(particles, element, (0, n, *tail), dtype, fill, self._clock)
            self._clock = group if self._clock is None else self._clock
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
        clock = self._clock
        self._edges = self._element(
            box, "edges", (0, 3, 3) if self._triclinic else (0, 3), np.float64, np.nan, clock
        )["value"]
        self._bounds = self._element(box, "pygran_bounds", (0, 3, 2), np.float64, np.nan, clock)["value"]
        self._tilt = (
            self._element(box, "pygran_tilt", (0, 3), np.float64, np.nan, clock)["value"]
            if self._triclinic
            else None
        )
        self._number = self._element(
            f.require_group(f"observables/{self.group}"), "particle_number", (0,), np.int64, -1, clock
        )["value"]
        self._columns = columns

    def _element(
        self, parent: Any, name: str, shape: tuple[int, ...], dtype: Any, fill: Any, clock: Any
    ) -> Any:
        """A time-dependent element: its ``step`` and ``time`` hard-linked from the element
        ``clock``, or made here when ``clock`` is None."""
        group = parent.create_group(name)
        if clock is None:
            group.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(1024,))
            group.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(1024,))
            if "time" in self.units:
                group["time"].attrs["unit"] = self.units["time"]
        else:
            group["step"] = clock["step"]
            group["time"] = clock["time"]
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
        contacts = frame.attrs.get("kind") == _contacts.KIND
        if self._file is None:
            if (self.contacts and contacts) or (not contacts and not frame.arrays):
                self._pending.append(frame)  # no particle columns yet to lay the file out with
                return
            self._create(None if contacts else frame)
            for pending in self._pending:
                self._dispatch(pending)
            self._pending.clear()
        self._dispatch(frame)

    def _dispatch(self, frame: Frame) -> None:
        if frame.attrs.get("kind") == _contacts.KIND:
            self._append_contacts(frame)
        else:
            self._append(frame)

    def _append_contacts(self, frame: Frame) -> None:
        if not self._contact_values:
            raise UnsupportedFeature(
                f"{self.path}: a contacts frame, but the file was laid out for particles only; open the "
                "writer with contacts=True"
            )
        try:
            arrays = _contacts.checked(frame.arrays, f"H5MD contacts frame {self.contact_count}")
        except ValueError as exc:
            raise UnsupportedFeature(str(exc)) from None
        n = len(arrays["id1"])
        k = self.contact_count
        step = frame.timestep if frame.timestep is not None else k
        for name, value in (("step", step), ("time", np.nan if frame.time is None else frame.time)):
            dataset = self._contact_clock[name]
            dataset.resize((k + 1,))
            dataset[k] = value
        for value, cols in self._contact_values:
            if n > value.shape[1]:
                value.resize(n, axis=1)
            value.resize(k + 1, axis=0)
            if n:
                value[k, :n] = (
                    np.column_stack([arrays[c] for c in cols]) if len(cols) == 3 else arrays[cols[0]]
                )
        self._contact_number.resize((k + 1,))
        self._contact_number[k] = n
        self._file.flush()
        self.contact_count += 1

    def _append(self, frame: Frame) -> None:
        if self._columns is None:
            raise UnsupportedFeature(f"{self.path}: a particle frame, but the file holds contacts only")
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
        box = np.asarray(frame.box if frame.box is not None else np.full((3, 2), np.nan), dtype=np.float64)
        lengths = box[:, 1] - box[:, 0]
        for dataset, row in (
            (self._edges, _edges(lengths, frame.attrs.get("tilt"), self._triclinic)),
            (self._bounds, box),
            (self._tilt, frame.attrs.get("tilt")),
        ):
            if dataset is not None:
                dataset.resize(k + 1, axis=0)
                dataset[k] = row
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


def open_hdf5(path: Path) -> Any:
    """``path`` opened for reading with h5py, or a :class:`ReadError`.

    The file is opened without SWMR, which checks its superblock and its size. Only a file
    that a writer left marked open (a writer killed before closing it, or one still writing)
    is then opened in SWMR mode, with HDF5's metadata read attempts bounded: an SWMR reader
    otherwise retries a damaged block with ever longer sleeps, which hangs on a truncated
    or damaged file.
    """
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            raise ReadError(f"{path}: not a readable HDF5 file: {exc}") from exc
    library = _hdf5_library()
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    if library is None or library.H5Pset_metadata_read_attempts(fapl.id, SWMR_READ_ATTEMPTS) < 0:
        raise ReadError(
            f"{path}: the file is still marked open by its writer (killed, or still running), and "
            "this platform's HDF5 cannot be read in SWMR mode safely; once no writer runs, clear "
            f"the mark with `h5clear -s {path}`"
        )
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    try:
        fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    except OSError as exc:
        raise ReadError(f"{path}: not a readable HDF5 file (left open by its writer): {exc}") from exc
    return h5py.File(fid)


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py runs on (found among the loaded libraries), for the one setting
    h5py does not expose, or None where it cannot be found."""
    import h5py  # noqa: F401 - loads the library

    names: list[str] = []
    try:
        with open("/proc/self/maps") as maps:  # Linux
            names = [
                fields[5].strip() for fields in (line.split(None, 5) for line in maps) if len(fields) == 6
            ]
    except OSError:
        try:  # macOS
            dyld = ctypes.CDLL(None)
            dyld._dyld_get_image_name.restype = ctypes.c_char_p
            names = [dyld._dyld_get_image_name(i).decode() for i in range(dyld._dyld_image_count())]
        except (OSError, AttributeError):
            return None
    for name in dict.fromkeys(n for n in names if "libhdf5" in Path(n).name and "hdf5_hl" not in n):
        try:
            library = ctypes.CDLL(name)
            setter = library.H5Pset_metadata_read_attempts
        except (OSError, AttributeError):
            continue
        setter.argtypes = [ctypes.c_int64, ctypes.c_uint]
        setter.restype = ctypes.c_int
        return library
    return None


def open_h5md(paths: Sequence[PathLike], group: str | None = None, contacts: bool = False) -> Trajectory:
    """The particle frames of an H5MD file, or its contact records when ``contacts=True`` or
    when it holds nothing else (``group=None``: the only group there is)."""
    if not contacts:
        try:
            return H5MDTrajectory(paths, group)
        except _ContactsOnly:
            pass
    return H5MDContacts(paths, group)


class _ContactsOnly(ReadError):
    """The file has no particles but contact records."""


class _H5MDFile(Trajectory):
    """One H5MD file open for reading, indexed by :meth:`_index`."""

    what = "particle"
    _n: int

    def __init__(self, paths: Sequence[PathLike], group: str | None = None) -> None:
        if len(paths) != 1:
            raise UnsupportedFeature(f"H5MD reads one file at a time, got {len(paths)}")
        self.path = Path(paths[0])
        self._file = open_hdf5(self.path)
        try:
            self._index(group)
        except ReadError:
            self._file.close()
            raise
        except _DAMAGE as exc:
            self._file.close()
            raise ReadError(f"{self.path}: not a readable H5MD {self.what} file: {exc}") from exc

    def _index(self, group: str | None) -> None:
        """Find the datasets of ``group`` and the frame count."""
        raise NotImplementedError

    def _fail(self, message: str) -> ReadError:
        return ReadError(f"{self.path}: {message}")

    def _root(self, top: str, group: str | None) -> Any:
        """The group ``/<top>/<group>`` (``group=None``: the only one), setting :attr:`group`."""
        import h5py

        parent = self._file[top]
        names = list(parent)
        if group is None:
            if len(names) != 1:
                raise self._fail(f"several {self.what} groups {names}; pass group=...")
            group = names[0]
        root = parent.get(group)
        if not isinstance(root, h5py.Group):
            raise self._fail(f"no {self.what} group {group!r}; the file has {names}")
        self.group = group
        return root

    def _boundary_of(self, box: Any) -> tuple[str, ...] | None:
        import h5py

        if isinstance(box, h5py.Group) and "pygran_boundary" in box.attrs:
            return tuple(_text(box.attrs["pygran_boundary"]).split())
        if isinstance(box, h5py.Group) and "boundary" in box.attrs:
            flags = [_text(b) for b in np.ravel(box.attrs["boundary"])]
            return tuple("pp" if b == "periodic" else "ff" for b in flags)
        return None

    def _dataset(self, group: Any, name: str, min_ndim: int, max_ndim: int) -> Any:
        """``group[name]``, which must be a numeric dataset of ``min_ndim`` to ``max_ndim`` axes."""
        import h5py

        found = group.get(name)
        if not isinstance(found, h5py.Dataset):
            raise self._fail(f"{group.name}/{name} is missing or not a dataset")
        if not min_ndim <= found.ndim <= max_ndim or found.dtype.kind not in "biuf":
            raise self._fail(f"{found.name} has shape {found.shape} and type {found.dtype}")
        return found

    @property
    def n_frames(self) -> int:
        return self._n

    def close(self) -> None:
        self._file.close()

    def _read_frame(self, index: int) -> Frame:
        try:
            return self._frame(index)
        except ReadError:
            raise
        except _DAMAGE as exc:
            raise self._fail(f"frame {index}: {exc}") from exc

    def _frame(self, index: int) -> Frame:
        raise NotImplementedError


class H5MDContacts(_H5MDFile):
    """The contact records of one H5MD file (``/contacts/<group>``), one frame each."""

    what = "contacts"

    def _index(self, group: str | None) -> None:
        import h5py

        top = self._file.get("contacts")
        if not isinstance(top, h5py.Group) or not len(top):
            raise self._fail("no /contacts group: the file holds no contact records")
        root = self._root("contacts", group)
        self._values: list[tuple[tuple[str, ...], Any]] = []
        for name in ("id1", "id2", *_contacts.VECTORS):
            element = root.get(name)
            if not isinstance(element, h5py.Group):
                raise self._fail(f"{root.name}/{name} is missing or not an H5MD element")
            ndim = 3 if name in _contacts.VECTORS else 2
            value = self._dataset(element, "value", ndim, ndim)
            if ndim == 3 and value.shape[2] != 3:
                raise self._fail(f"{value.name} has shape {value.shape}, not (frames, contacts, 3)")
            self._values.append((_contacts.VECTORS.get(name, (name,)), value))
        clock = root["id1"]
        self._step, self._time = self._dataset(clock, "step", 1, 1), self._dataset(clock, "time", 1, 1)
        number = self._file.get(f"observables/{self.group}/contact_number")
        if not isinstance(number, h5py.Group):
            raise self._fail(f"/observables/{self.group}/contact_number is missing: the contacts per frame")
        self._number = self._dataset(number, "value", 1, 1)
        lengths = [len(v) for _, v in self._values] + [len(self._step), len(self._time), len(self._number)]
        self._n = min(lengths)
        self._boundary = self._boundary_of(self._file.get(f"particles/{self.group}/box"))

    def _frame(self, index: int) -> Frame:
        count = int(self._number[index])
        arrays: dict[str, np.ndarray] = {}
        for columns, value in self._values:
            if not 0 <= count <= value.shape[1]:
                raise self._fail(f"frame {index}: {count} contacts, but {value.name} holds {value.shape[1]}")
            data = value[index, :count]
            kind = np.int64 if columns[0] in _contacts.INT_COLUMNS else np.float64
            if data.dtype.kind not in "biuf":
                raise self._fail(f"frame {index}: {value.name} has type {data.dtype}")
            data = data.astype(kind)
            if data.ndim == 2:
                arrays.update({c: np.ascontiguousarray(data[:, j]) for j, c in enumerate(columns)})
            else:
                arrays[columns[0]] = data
        time = float(self._time[index])
        return Frame(
            {c: arrays[c] for c in _contacts.COLUMNS},
            timestep=int(self._step[index]),
            time=None if np.isnan(time) else time,
            boundary=self._boundary,
            attrs={"kind": _contacts.KIND},
        )


class H5MDTrajectory(_H5MDFile):
    """Frames of one H5MD file's particle group (``group=None``: the only one there is)."""

    def _index(self, group: str | None) -> None:
        import h5py

        particles = self._file.get("particles")
        if not isinstance(particles, h5py.Group) or not len(particles):
            if isinstance(self._file.get("contacts"), h5py.Group):
                raise _ContactsOnly(f"{self.path}: holds contact records only")
            raise self._fail("no /particles group: not an H5MD trajectory")
        root = self._root("particles", group)
        #: (name, dataset, time-dependent) of every element but the box
        self._elements: list[tuple[str, Any, bool]] = []
        clock = None
        for name, obj in root.items():
            if name == "box":
                continue
            if isinstance(obj, h5py.Group):
                clock = obj if clock is None else clock
                self._elements.append((name, self._dataset(obj, "value", 2, 3), True))
            elif isinstance(obj, h5py.Dataset):
                self._elements.append((name, obj, False))
        if clock is None:
            raise self._fail(f"particle group {group!r} has no time-dependent element")
        self._step, self._time = self._dataset(clock, "step", 1, 1), self._dataset(clock, "time", 1, 1)
        lengths = [len(d) for _, d, timed in self._elements if timed] + [len(self._step), len(self._time)]
        number = self._file.get(f"observables/{group}/particle_number")
        self._number = None if number is None else self._dataset(number, "value", 1, 1)
        if self._number is not None:
            lengths.append(len(self._number))
        box = root.get("box")
        self._box_parts: dict[str, Any] = {}
        if isinstance(box, h5py.Group):
            for part, dims in (("edges", (2, 3)), ("pygran_bounds", (3, 3)), ("pygran_tilt", (2, 2))):
                if isinstance(box.get(part), h5py.Group):
                    self._box_parts[part] = self._dataset(box[part], "value", *dims)
                    lengths.append(len(self._box_parts[part]))
        self._n = min(lengths)
        self._boundary = self._boundary_of(box)

    def contacts(self) -> Trajectory | None:
        """The contact records of this particle group stored in the same file, if any."""
        if f"contacts/{self.group}" not in self._file:
            return None
        return H5MDContacts([self.path], self.group)

    def _frame(self, index: int) -> Frame:
        count = int(self._number[index]) if self._number is not None else None
        rows: dict[str, np.ndarray] = {}
        for name, dataset, timed in self._elements:
            data = dataset[index] if timed else dataset[()]
            if data.ndim == 0 or data.dtype.kind not in "biuf":
                raise self._fail(f"frame {index}: element {name!r} has shape {data.shape}, type {data.dtype}")
            if count is None and name == "id":
                count = int(np.count_nonzero(data >= 0))
            rows[name] = data
        arrays: dict[str, np.ndarray] = {}
        for name, data in rows.items():
            if count is not None:
                if not 0 <= count <= len(data):
                    raise self._fail(f"frame {index}: {count} particles, but {name!r} holds {len(data)}")
                data = data[:count]
            data = data.astype(np.int64 if data.dtype.kind in "biu" else np.float64)
            if name in VECTORS and data.shape[1:] == (3,):
                for j, column in enumerate(VECTORS[name]):
                    arrays[column] = np.ascontiguousarray(data[:, j])
            elif data.ndim == 2:
                for j in range(data.shape[1]):
                    arrays[f"{name}[{j + 1}]"] = np.ascontiguousarray(data[:, j])
            elif data.ndim == 1:
                arrays["type" if name == "species" else name] = data
            else:
                raise self._fail(f"frame {index}: element {name!r} has shape {data.shape}")
        if len({len(v) for v in arrays.values()}) > 1:
            raise self._fail(f"frame {index}: the elements hold different particle counts")
        box, attrs = None, {}
        if "pygran_bounds" in self._box_parts:
            box = np.asarray(self._box_parts["pygran_bounds"][index], dtype=np.float64).reshape(3, 2)
        elif "edges" in self._box_parts:
            edges = np.asarray(self._box_parts["edges"][index], dtype=np.float64)
            lengths = np.diag(edges.reshape(3, 3)) if edges.size == 9 else edges.reshape(3)
            box = np.column_stack([np.zeros(3), lengths])
        if box is not None and np.isnan(box).all():
            box = None
        if "pygran_tilt" in self._box_parts:
            attrs["tilt"] = np.asarray(self._box_parts["pygran_tilt"][index], dtype=np.float64).reshape(3)
        time = float(self._time[index])
        return Frame(
            arrays,
            timestep=int(self._step[index]),
            time=None if np.isnan(time) else time,
            box=box,
            boundary=self._boundary,
            attrs=attrs,
        )


def _text(value: Any) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)
