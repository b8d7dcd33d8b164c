"""HDF5 trajectories in the H5MD 1.1 layout (https://www.nongnu.org/h5md/), read and written.

Layout written (``<g>`` is the particle group, ``trajectory`` by default: the name MDAnalysis
looks for)::

    /h5md                         version = [1, 1]; author/, creator/ with a name attribute;
                                  modules/units (system "SI") when the units are SI
    /particles/<g>/box            dimension = 3, boundary = periodic|none per axis
        edges/{step,time,value}   (F, 3) box lengths (F, 3, 3) box vectors when triclinic
        pygran_bounds/...         (F, 3, 2) the exact dump bounds; pygran_tilt (F, 3) if any
    /particles/<g>/<element>/{step,time,value}
        position, velocity, force, image, angular_velocity, torque   (F, N, 3) from
            x y z, vx vy vz, fx fy fz, ix iy iz, omegax omegay omegaz, tqx tqy tqz
        id (F, N) int, -1 where a row holds no particle; species (F, N) from ``type``;
        any other column (F, N)
        pygran_order (F, N) int: where each row's particle stood in the frame as written
    /observables/<g>/particle_number/{step,time,value}   (F,) particles in each frame

Rows are identities: a particle keeps the row it got at its first frame for the whole file
(LAMMPS' ``dump h5md`` and MDAnalysis take row i to be one particle throughout); rows of
particles absent from a frame hold the fill values (id -1, NaN), as the H5MD ``id`` element
specifies. Frames without an ``id`` column fill rows in order. Every ``value`` with a physical
dimension carries its ``unit`` attribute (H5MD units module), and so does every ``time``.

Contact records (:mod:`~pygran_core.formats.contacts`), when written, in the same layout::

    /contacts/<g>/{id1,id2}/{step,time,value}             (F, C) int, padded with 0
    /contacts/<g>/{force,point,branch}/{step,time,value}  (F, C, 3) fx fy fz, cx cy cz, bx by bz
    /observables/<g>/contact_number/{step,time,value}     (F,) contacts in each frame

Every ``value`` is chunked (a frame and up to 65,536 rows per chunk, sized by the first
particle frame) and resizable in frames and rows; gzip-compressed unless that frame has 65,536
particles or more (see :class:`H5MDWriter`); HDF5 stores no chunk that holds fill values only.
Frames are written and read block by block of whole chunks, straight from and into the
columns where their rows allow, so a frame of 10^7 particles goes at disk speed with buffers
of a few MB. ``step`` and ``time`` are one pair of datasets hard-linked
into every element of a group (particles, contacts). The file is written in SWMR mode and
flushed after every frame, so a killed writer leaves every completed frame readable;
``particle_number`` and ``contact_number`` are written last and set the frame counts. Next to
the file, the XDMF sidecar (:mod:`~pygran_core.formats.xdmf`) shows the particles in ParaView.

Reading gives SI values: an element whose ``unit`` is another (nm, ps, Angstrom,
kJ mol-1 nm-1, as molecular codes write them) is converted (:mod:`~pygran_core.formats.h5md_units`),
one whose unit is unknown or of the wrong dimension refused.

Reading checks what a file from elsewhere may get wrong: it must be self-contained
(:func:`~pygran_core.formats.hdf5.open_hdf5`), its elements must agree in frames and rows,
vectors must have 3 components, ids and species must be integers, no element may be a sparse
shell larger than what it stores, steps must increase, and every frame must be physically sane
(:mod:`~pygran_core.formats.sanity`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pygran_core.errors import PyGranError, ReadError, UnsupportedFeature, WriteError
from pygran_core.formats import contacts as _contacts
from pygran_core.formats.base import Frame, PathLike, Trajectory, TrajectoryWriter
from pygran_core.formats.h5md_units import to_si
from pygran_core.formats.hdf5 import HDF5_SIGNATURE, Claim, load_h5py, no_space, open_hdf5, stored_elements
from pygran_core.formats.sanity import particle_problem, step_problem
from pygran_core.formats.xdmf import VECTORS, XdmfSidecar, interleaved, stacked

#: H5MD scalar element names that differ from the dump column.
RENAMED = {"type": "species"}
#: Elements whose values are integers.
INTEGER_ELEMENTS = ("id", "species", "image", "pygran_order")
#: The H5MD unit strings of SI data (H5MD units module; the force as "N", which MDAnalysis reads).
SI_UNITS = {
    "position": "m",
    "velocity": "m s-1",
    "force": "N",
    "angular_velocity": "rad s-1",
    "torque": "N m",
    "radius": "m",
    "diameter": "m",
    "mass": "kg",
    "density": "kg m-3",
    "time": "s",
    "edges": "m",
    "pygran_bounds": "m",
    "pygran_tilt": "m",
    "point": "m",  # contacts
    "branch": "m",
}
#: What h5py raises on a damaged file (HDF5's own errors are OSError, RuntimeError, KeyError
#: or ValueError; an object of the wrong kind gives TypeError or IndexError).
_DAMAGE = (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError)
#: Particle rows of a chunk at least and at most (a chunk of a vector element holds at most
#: 1.5 MB): the first particle frame's rows in as few chunks as these allow, of equal size.
CHUNK_ROWS = (1024, 65536)
#: Frames of this many particles or more are written without compression by default.
LARGE_FRAME = 65536
#: Rows read or written per HDF5 call when a frame's rows are gathered or spread (cut at
#: multiples of whole chunks): the buffers of a frame's columns stay this small.
BLOCK_ROWS = 65536


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


class _Rows:
    """The row of the (frames, rows) arrays that holds each particle id: the next free row at
    the particle's first frame, kept for good.

    Looked up in a table indexed by id while the ids are few times more than the rows (ids
    numbered from 1, as engines give them), else by a search in the sorted ids; both are
    numpy operations over the frame, never a loop over particles.
    """

    def __init__(self) -> None:
        self.count = 0
        self._table: np.ndarray | None = np.empty(0, dtype=np.int64)  # row of each id, -1: none
        self._ids = np.empty(0, dtype=np.int64)  # sorted, once the table is given up
        self._rows = np.empty(0, dtype=np.int64)

    def of(self, ids: np.ndarray) -> np.ndarray:
        """The rows of ``ids`` (unique, not negative), giving new ids the next free rows in
        their order."""
        top = int(ids.max())
        if self._table is not None and top >= 4 * (self.count + len(ids)) + BLOCK_ROWS:
            self._ids = np.flatnonzero(self._table >= 0)
            self._rows, self._table = self._table[self._ids], None
        if self._table is None:
            return self._searched(ids)
        if top >= len(self._table):
            grown = np.full(max(top + 1, 2 * len(self._table)), -1, dtype=np.int64)
            grown[: len(self._table)] = self._table
            self._table = grown
        rows = self._table[ids]
        fresh = np.flatnonzero(rows < 0)
        rows[fresh] = self.count + np.arange(len(fresh))
        self._table[ids[fresh]] = rows[fresh]
        self.count += len(fresh)
        return rows

    def _searched(self, ids: np.ndarray) -> np.ndarray:
        where = np.searchsorted(self._ids, ids)
        known = where < len(self._ids)
        known[known] = self._ids[where[known]] == ids[known]
        rows = np.empty(len(ids), dtype=np.int64)
        rows[known] = self._rows[where[known]]
        fresh = np.flatnonzero(~known)
        rows[fresh] = self.count + np.arange(len(fresh))
        self.count += len(fresh)
        if len(fresh):
            ids_all = np.concatenate([self._ids, ids[fresh]])
            rows_all = np.concatenate([self._rows, rows[fresh]])
            order = np.argsort(ids_all, kind="stable")
            self._ids, self._rows = ids_all[order], rows_all[order]
        return rows


class _Placement(NamedTuple):
    """Where a frame's particles are in the rows ``lo`` to ``hi`` of the file: ``where[r - lo]``
    is the frame's particle in row r (-1: none); ``where`` None: particle i is in row lo + i."""

    lo: int
    hi: int
    where: np.ndarray | None

    @classmethod
    def of(cls, rows: np.ndarray, order: np.ndarray | None = None) -> _Placement:
        """The placement of particles ``order[i]`` (``i`` without ``order``) in ``rows[i]``
        (unique)."""
        if not len(rows):
            return cls(0, 0, None)
        lo, hi = int(rows.min()), int(rows.max()) + 1
        ordered = order is None or bool((order[1:] > order[:-1]).all())
        if ordered and hi - lo == len(rows) and bool((rows[1:] > rows[:-1]).all()):
            return cls(lo, hi, None)
        where = np.full(hi - lo, -1, dtype=np.int64)
        where[rows - lo] = np.arange(len(rows)) if order is None else order
        return cls(lo, hi, where)


def _block_rows(chunk: int | None) -> int:
    """The rows of a block: whole chunks of ``chunk`` rows (None: not chunked), about
    :data:`BLOCK_ROWS`."""
    return BLOCK_ROWS if chunk is None else chunk * max(1, BLOCK_ROWS // chunk)


def _blocks(lo: int, hi: int, chunk: int | None) -> Iterator[tuple[int, int]]:
    """(start, stop) of the rows ``lo`` to ``hi`` cut at the multiples of :func:`_block_rows`."""
    step = _block_rows(chunk)
    start = lo
    while start < hi:
        stop = min(hi, (start // step + 1) * step)
        yield start, stop
        start = stop


def _write_rows(value: Any, k: int, columns: list[np.ndarray] | None, place: _Placement) -> None:
    """Frame ``k`` of the (frames, rows[, components]) dataset ``value``: ``columns`` (one per
    component) in the rows of ``place``, or None: each row's particle index (``pygran_order``).

    Columns that are one contiguous array of the dataset's type (a scalar column, or x y z
    as an engine gives them) in rows taken in order go to the file as they are; others through
    a buffer of a block of rows."""
    lo, hi, where = place
    if where is None and columns is not None:
        whole = stacked(columns) if len(columns) == 1 else interleaved(columns)
        if whole is not None and whole.dtype == value.dtype and whole.flags.c_contiguous:
            value.write_direct(whole, dest_sel=np.s_[k, lo:hi])
            return
    buffer = np.empty((min(hi - lo, _block_rows(value.chunks[1])), *value.shape[2:]), dtype=value.dtype)
    for start, stop in _blocks(lo, hi, value.chunks[1]):
        part = buffer[: stop - start]
        grid = part.reshape(len(part), -1)  # a view, (rows, components)
        if where is None:
            taken = slice(start - lo, stop - lo)
            sources = [np.arange(start - lo, stop - lo)] if columns is None else [c[taken] for c in columns]
            for j, source in enumerate(sources):
                grid[:, j] = source
        else:
            particles = where[start - lo : stop - lo]
            if columns is None:
                grid[:, 0] = particles
            else:
                present = particles >= 0
                part[...] = value.fillvalue
                for j, column in enumerate(columns):
                    grid[present, j] = column[particles[present]]
        value.write_direct(part, dest_sel=np.s_[k, start:stop])


def _read_rows(dataset: Any, index: int | None, place: _Placement, n: int) -> list[np.ndarray]:
    """The ``n`` particles of ``place`` in frame ``index`` of the (frames, rows[, components])
    dataset ``dataset`` (``index`` None: a (rows[, components]) dataset of every frame): one
    new contiguous int64 or float64 array per component, read into directly (a scalar in
    rows taken in order) or through a buffer of a block of rows."""
    lead = () if index is None else (index,)
    tail = dataset.shape[len(lead) + 1 :]
    kind = np.int64 if dataset.dtype.kind in "biu" else np.float64
    columns = [np.empty(n, dtype=kind) for _ in range(int(np.prod(tail, dtype=np.int64)))]
    lo, hi, where = place
    if where is None and not tail and dataset.dtype.kind != "b":  # HDF5 converts numbers only
        if n:
            dataset.read_direct(columns[0], (*lead, slice(lo, hi)))
        return columns
    chunk = dataset.chunks[len(lead)] if dataset.chunks else None
    buffer = np.empty((min(hi - lo, _block_rows(chunk)), *tail), dtype=dataset.dtype)
    for start, stop in _blocks(lo, hi, chunk):
        part = buffer[: stop - start]
        dataset.read_direct(part, (*lead, slice(start, stop)))
        grid = part.reshape(len(part), -1)  # a view, (rows, components)
        if where is None:
            for j, column in enumerate(columns):
                column[start - lo : stop - lo] = grid[:, j]
        else:
            to = where[start - lo : stop - lo]
            present = to >= 0
            for j, column in enumerate(columns):
                column[to[present]] = grid[present, j]
    return columns


def _permutes(order: np.ndarray) -> bool:
    """Whether ``order`` (not empty) holds 0 to len(order) - 1 once each."""
    if order.min() < 0 or order.max() >= len(order):
        return False
    seen = np.zeros(len(order), dtype=bool)
    seen[order] = True
    return bool(seen.all())


class H5MDWriter(TrajectoryWriter):
    """Appends particle frames, and contacts frames, to an H5MD file, flushing each one, and
    the XDMF sidecar of the particle frames (``xdmf=False``: none).

    Options: ``group`` (particle group name), ``units`` (``"si"``, the default: the data are
    in SI units; a mapping from element name to unit string; or None: no ``unit``
    attributes), ``compression`` level (gzip 1-9, 0: none; by default 4 for a file whose
    first particle frame has fewer than :data:`LARGE_FRAME` particles, none for larger ones:
    gzip writes tens of MB/s, a small part of what a disk takes, and saves mostly the columns
    that hardly change, such as ``type`` and ``radius``), ``contacts``: whether contacts frames
    (``attrs["kind"] == "contacts"``) come besides the particle frames (the file is laid out
    for both at its first particle frame with columns). A writer whose first frame is a
    contacts frame, without ``contacts=True``, writes a file of contacts only.

    A frame goes to the file without copies where it can: a column, or x y z given as the
    columns of one (N, 3) array, in rows taken in order (the same particles as in the frame
    before, or new ones after them); otherwise through buffers of :data:`BLOCK_ROWS` rows.

    The file is claimed before it is emptied (a second writer of the same file gets a
    :class:`~pygran_core.errors.WriteError` and the first one's file is untouched), and
    each frame's disk space is reserved before it is written: a full disk gives one
    ``WriteError`` naming the file, with every earlier frame readable.
    """

    def __init__(
        self,
        path: PathLike,
        group: str = "trajectory",
        units: str | dict[str, str] | None = "si",
        compression: int | None = None,
        contacts: bool = False,
        xdmf: bool = True,
    ) -> None:
        if isinstance(units, str) and units != "si":
            raise UnsupportedFeature(f"H5MD units must be 'si', a mapping or None, got {units!r}")
        self.path = Path(path)
        self.group = group
        self.units = SI_UNITS if isinstance(units, str) else dict(units or {})
        self.si = isinstance(units, str)
        self.compression = compression
        self.contacts = contacts
        self.xdmf = xdmf
        self.count = 0
        self.contact_count = 0
        self._chunk_rows = CHUNK_ROWS[0]
        self._file: Any = None
        self._claim: Claim | None = None
        self._sidecar: XdmfSidecar | None = None
        self._failed: str | None = None
        self._columns: list[str] | None = None
        self._boundary: tuple[str, ...] | None = None
        self._pending: list[Frame] = []
        self._contact_values: list[tuple[Any, tuple[str, ...]]] = []
        self._rows = _Rows()
        self._last_step: int | None = None

    # -- file creation ---------------------------------------------------------------------
    def _create(self, frame: Frame | None) -> None:
        """The file, laid out for the particle frame ``frame`` (None: contacts only) and, if
        asked or if ``frame`` is None, for contacts; then in SWMR mode. Its particle count
        sets the chunks' rows and the default compression."""
        h5py = load_h5py()

        n = len(next(iter(frame.arrays.values()))) if frame is not None and frame.arrays else 0
        self._chunk_rows = max(CHUNK_ROWS[0], -(-n // -(-n // CHUNK_ROWS[1])) if n else 0)
        if self.compression is None:
            self.compression = 0 if n >= LARGE_FRAME else 4
        self._claim = Claim(self.path)
        self._claim.truncate()
        # without HDF5's own file lock, which a reader in another process would hold against
        # this writer; the claim excludes other writers
        # no chunk cache: each chunk of a frame is written once, whole
        self._file = f = h5py.File(
            self.path, "w", libver="latest", track_order=True, locking=False, rdcc_nbytes=0
        )
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array([1, 1], dtype=np.int32)
        h5md.create_group("author").attrs["name"] = "PyGran"
        creator = h5md.create_group("creator")
        creator.attrs["name"] = "PyGran"
        creator.attrs["version"] = version("pygran-core")
        if self.si:
            units = h5md.create_group("modules/units")
            units.attrs["version"] = np.array([1, 0], dtype=np.int32)
            units.attrs["system"] = "SI"
        if frame is not None:
            self._layout_particles(f, frame)
        if self.contacts or frame is None:
            self._layout_contacts(f)
        f.swmr_mode = True

    def _layout_contacts(self, f: Any) -> None:
        root = f.create_group(f"contacts/{self.group}", track_order=True)
        clock: Any = None
        for name in ("id1", "id2"):
            group = self._element(root, name, (0, 1), np.int64, 0, clock, CHUNK_ROWS[0])
            clock = group if clock is None else clock
            self._contact_values.append((group["value"], (name,)))
        for name, cols in _contacts.VECTORS.items():
            group = self._element(root, name, (0, 1, 3), np.float64, np.nan, clock, CHUNK_ROWS[0])
            self._contact_values.append((group["value"], cols))
        self._contact_clock = clock
        observables = f.require_group(f"observables/{self.group}")
        self._contact_number = self._element(observables, "contact_number", (0,), np.int64, -1, clock)[
            "value"
        ]

    def _layout_particles(self, f: Any, frame: Frame) -> None:
        h5py = load_h5py()

        columns = list(frame.arrays)
        bad = [c for c in columns if np.ndim(frame.arrays[c]) != 1]
        if bad:
            raise UnsupportedFeature(f"H5MD particle columns must be 1-D; {bad} are not (a mesh frame?)")
        particles = f.create_group(f"particles/{self.group}", track_order=True)
        self._clock: Any = None  # the element holding the step and time datasets
        self._values: list[tuple[Any, tuple[str, ...]]] = []
        self._elements = _elements(columns)
        for element, cols in self._elements:
            integer = element in INTEGER_ELEMENTS or np.asarray(frame.arrays[cols[0]]).dtype.kind in "iub"
            dtype = np.int64 if integer else np.float64
            fill = -1 if integer else np.nan
            tail = (3,) if len(cols) == 3 else ()
            group = self._element(
                particles, element, (0, 0, *tail), dtype, fill, self._clock, self._chunk_rows
            )
            self._clock = group if self._clock is None else self._clock
            self._values.append((group["value"], cols))
        self._order = None
        if "id" in columns:
            self._order = self._element(
                particles, "pygran_order", (0, 0), np.int64, -1, self._clock, self._chunk_rows
            )["value"]
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
        if self.xdmf and "position" in dict(self._elements):
            self._sidecar = XdmfSidecar(self.path, self.compression or 0)

    def _element(
        self,
        parent: Any,
        name: str,
        shape: tuple[int, ...],
        dtype: Any,
        fill: Any,
        clock: Any,
        rows: int | None = None,
    ) -> Any:
        """A time-dependent element: its ``step`` and ``time`` hard-linked from the element
        ``clock``, or made here when ``clock`` is None; a chunk per frame, of ``rows`` rows
        (particles or contacts, the second axis) or the whole frame (None)."""
        group = parent.create_group(name)
        if clock is None:
            group.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(1024,))
            group.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(1024,))
            if "time" in self.units:
                group["time"].attrs["unit"] = self.units["time"]
        else:
            group["step"] = clock["step"]
            group["time"] = clock["time"]
        chunks = (1, *(max(s, 1) for s in shape[1:])) if rows is None else (1, rows, *shape[2:])
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
        if self._failed is not None:
            raise WriteError(
                f"{self.path}: nothing more is written after an earlier failure ({self._failed})"
            )
        try:
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
        except WriteError as exc:
            self._fail(str(exc))
            raise
        except (OSError, RuntimeError) as exc:  # HDF5 failing to write
            why = "no space left" if no_space(exc) else str(exc)
            self._fail(why)
            raise WriteError(f"{self.path}: frame {self.count} could not be written: {why}") from None

    def _fail(self, why: str) -> None:
        """Stop writing, leaving the frames written so far readable."""
        self._failed = why
        self.close()

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
        assert self._claim is not None
        self._claim.reserve(sum(a.nbytes for a in arrays.values()))
        step = frame.timestep if frame.timestep is not None else k
        for name, value in (("step", step), ("time", np.nan if frame.time is None else frame.time)):
            dataset = self._contact_clock[name]
            dataset.resize((k + 1,))
            dataset[k] = value
        for value, cols in self._contact_values:
            value.resize((k + 1, max(n, value.shape[1]), *value.shape[2:]))
            if n:
                _write_rows(value, k, [np.asarray(arrays[c]) for c in cols], _Placement(0, n, None))
        self._contact_number.resize((k + 1,))
        self._contact_number[k] = n
        self._file.flush()
        self.contact_count += 1

    def _checked(self, frame: Frame) -> tuple[int, _Placement]:
        """The frame's particle count and rows, once its columns, ids and step are right."""
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
        step = frame.timestep if frame.timestep is not None else self.count
        problem = step_problem(self._last_step, step) or particle_problem(frame.arrays)
        n = len(next(iter(frame.arrays.values()))) if frame.arrays else 0
        ids = np.asarray(frame.arrays["id"], dtype=np.int64) if "id" in self._columns and n else None
        if ids is not None and ids.min() < 0:
            problem = problem or f"negative ids (such as {ids.min()}): H5MD marks absent particles with -1"
        if problem:
            raise UnsupportedFeature(f"H5MD frame {self.count}: {problem}")
        if ids is None:
            self._rows.count = max(self._rows.count, n)
            return n, _Placement(0, n, None)
        return n, _Placement.of(self._rows.of(ids))

    def _append(self, frame: Frame) -> None:
        n, place = self._checked(frame)
        k = self.count
        assert self._claim is not None
        self._claim.reserve(
            sum(8 * (place.hi - place.lo) * (3 if v.ndim == 3 else 1) for v, _ in self._values)
        )
        step = frame.timestep if frame.timestep is not None else k
        for name, value in (("step", step), ("time", np.nan if frame.time is None else frame.time)):
            dataset = self._clock[name]
            dataset.resize((k + 1,))
            dataset[k] = value
        order = [(self._order, None)] if self._order is not None else []
        for value, cols in [*self._values, *order]:
            value.resize((k + 1, max(self._rows.count, value.shape[1]), *value.shape[2:]))
            if n:
                columns = None if cols is None else [np.asarray(frame.arrays[c]) for c in cols]
                _write_rows(value, k, columns, place)
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
        self._last_step = step
        if self._sidecar is not None:
            time = float(step) if frame.time is None or np.isnan(frame.time) else float(frame.time)
            self._sidecar.add(k, step, time, frame.arrays, self._elements)

    def close(self) -> None:
        if self._file is None and self._pending and self._failed is None:
            raise UnsupportedFeature("H5MD: no frame with particle columns was written; nothing to lay out")
        for resource in (self._file, self._sidecar, self._claim):
            if resource is not None:
                try:
                    resource.close()
                except (OSError, RuntimeError, PyGranError):
                    pass  # the failure that stopped the writer was reported
        self._file = self._sidecar = self._claim = None


def _edges(lengths: np.ndarray, tilt: Any, triclinic: bool) -> np.ndarray:
    if not triclinic:
        return lengths
    xy, xz, yz = np.asarray(tilt, dtype=np.float64)
    return np.array([[lengths[0], 0, 0], [xy, lengths[1], 0], [xz, yz, lengths[2]]])


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
    _step: Any  # the step and time datasets of the frames
    _time: Any

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
        h5py = load_h5py()

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
        h5py = load_h5py()

        if isinstance(box, h5py.Group) and "pygran_boundary" in box.attrs:
            return tuple(_text(box.attrs["pygran_boundary"]).split())
        if isinstance(box, h5py.Group) and "boundary" in box.attrs:
            flags = [_text(b) for b in np.ravel(box.attrs["boundary"])]
            return tuple("pp" if b == "periodic" else "ff" for b in flags)
        return None

    def _dataset(self, group: Any, name: str, min_ndim: int, max_ndim: int) -> Any:
        """``group[name]``, which must be a numeric dataset of ``min_ndim`` to ``max_ndim`` axes,
        opened without a chunk cache: frames are read in whole chunks, each once, and HDF5's
        cache would keep up to 8 MB of each dataset's last chunks (many frames of a small
        trajectory) for nothing."""
        h5py = load_h5py()

        if name not in group or group.get(name, getclass=True) is not h5py.Dataset:
            raise self._fail(f"{group.name}/{name} is missing or not a dataset")
        uncached = h5py.h5p.create(h5py.h5p.DATASET_ACCESS)
        uncached.set_chunk_cache(0, 0, 1.0)
        found = h5py.Dataset(h5py.h5d.open(group.id, name.encode(), dapl=uncached))  # the first opening
        if not min_ndim <= found.ndim <= max_ndim or found.dtype.kind not in "biuf":
            raise self._fail(f"{found.name} has shape {found.shape} and type {found.dtype}")
        return found

    def _si(self, name: str, dataset: Any) -> float:
        """The factor that turns the values of ``dataset`` (of element ``name``) into SI, from
        its ``unit`` attribute (none: SI); a unit that is unknown or wrong is a ReadError."""
        unit = dataset.attrs.get("unit")
        if unit is None or dataset.dtype.kind in "biu":
            return 1.0
        try:
            return to_si(name, _text(unit))
        except ValueError as exc:
            raise self._fail(f"{dataset.name}: {exc}") from None

    def _time_at(self, index: int) -> float | None:
        time = float(self._time[index]) * self._time_factor
        return None if np.isnan(time) else time

    def _check_clock(self) -> None:
        """Refuse steps that do not increase, or times that decrease, over the frames."""
        self._time_factor = self._si("time", self._time)
        steps = self._step[: self._n]
        if self._step.dtype.kind not in "iu":
            raise self._fail(f"{self._step.name} holds {self._step.dtype}: steps must be integers")
        for k in np.flatnonzero(np.diff(steps) <= 0)[:1]:
            raise self._fail(f"frame {k + 1}: {step_problem(int(steps[k]), int(steps[k + 1]))}")
        times = self._time[: self._n]
        known = times[~np.isnan(times)]
        if (np.diff(known) < 0).any():
            raise self._fail(f"{self._time.name}: times decrease from frame to frame")

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
        h5py = load_h5py()

        top = self._file.get("contacts")
        if not isinstance(top, h5py.Group) or not len(top):
            raise self._fail("no /contacts group: the file holds no contact records")
        root = self._root("contacts", group)
        self._values: list[tuple[tuple[str, ...], Any, float]] = []  # columns, dataset, factor to SI
        for name in ("id1", "id2", *_contacts.VECTORS):
            element = root.get(name)
            if not isinstance(element, h5py.Group):
                raise self._fail(f"{root.name}/{name} is missing or not an H5MD element")
            ndim = 3 if name in _contacts.VECTORS else 2
            value = self._dataset(element, "value", ndim, ndim)
            if ndim == 3 and value.shape[2] != 3:
                raise self._fail(f"{value.name} has shape {value.shape}, not (frames, contacts, 3)")
            self._values.append((_contacts.VECTORS.get(name, (name,)), value, self._si(name, value)))
        clock = root["id1"]
        self._step, self._time = self._dataset(clock, "step", 1, 1), self._dataset(clock, "time", 1, 1)
        number = self._file.get(f"observables/{self.group}/contact_number")
        if not isinstance(number, h5py.Group):
            raise self._fail(f"/observables/{self.group}/contact_number is missing: the contacts per frame")
        self._number = self._dataset(number, "value", 1, 1)
        lengths = [len(v) for _, v, _ in self._values] + [len(self._step), len(self._time), len(self._number)]
        self._n = min(lengths)
        self._check_clock()
        self._boundary = self._boundary_of(self._file.get(f"particles/{self.group}/box"))

    def _frame(self, index: int) -> Frame:
        count = int(self._number[index])
        arrays: dict[str, np.ndarray] = {}
        for columns, value, factor in self._values:
            if not 0 <= count <= value.shape[1]:
                raise self._fail(f"frame {index}: {count} contacts, but {value.name} holds {value.shape[1]}")
            kind = np.int64 if columns[0] in _contacts.INT_COLUMNS else np.float64
            read = _read_rows(value, index, _Placement(0, count, None), count)
            for column, data in zip(columns, read):
                arrays[column] = data.astype(kind, copy=False)
                if factor != 1:
                    arrays[column] *= factor
        return Frame(
            {c: arrays[c] for c in _contacts.COLUMNS},
            timestep=int(self._step[index]),
            time=self._time_at(index),
            boundary=self._boundary,
            attrs={"kind": _contacts.KIND},
        )


class H5MDTrajectory(_H5MDFile):
    """Frames of one H5MD file's particle group (``group=None``: the only one there is).

    A frame holds the rows whose ``id`` is not -1 (all rows without an ``id`` element; the
    first ``particle_number`` rows without either), in the order they were written
    (``pygran_order``) or else in row order.
    """

    def _index(self, group: str | None) -> None:
        h5py = load_h5py()

        particles = self._file.get("particles")
        if not isinstance(particles, h5py.Group) or not len(particles):
            if isinstance(self._file.get("contacts"), h5py.Group):
                raise _ContactsOnly(f"{self.path}: holds contact records only")
            raise self._fail("no /particles group: not an H5MD trajectory")
        root = self._root("particles", group)
        #: (name, dataset, time-dependent) of every element but the box and the order
        self._elements: list[tuple[str, Any, bool]] = []
        self._order: Any = None
        self._rows: int | None = None  # particles per frame, and the element that says so
        self._rows_from = ""
        self._factors: dict[str, float] = {}  # to SI, by element
        clock = None
        for name, obj in root.items():
            if name == "box":
                continue
            timed = isinstance(obj, h5py.Group)
            dataset = self._dataset(obj, "value", 2, 3) if timed else self._dataset(root, name, 1, 2)
            self._check_element(name, dataset, timed)
            if timed:
                clock = obj if clock is None else clock
            if name == "pygran_order":
                self._order = dataset
            else:
                self._elements.append((name, dataset, timed))
                self._factors[name] = self._si(name, dataset)
        if clock is None:
            raise self._fail(f"particle group {self.group!r} has no time-dependent element")
        self._step, self._time = self._dataset(clock, "step", 1, 1), self._dataset(clock, "time", 1, 1)
        lengths = [len(d) for _, d, timed in self._elements if timed] + [len(self._step), len(self._time)]
        number = self._file.get(f"observables/{self.group}/particle_number")
        self._number = None if number is None else self._dataset(number, "value", 1, 1)
        if self._number is not None:
            lengths.append(len(self._number))
        self._ids = next((d for name, d, timed in self._elements if name == "id" and timed), None)
        box = root.get("box")
        self._box_parts: dict[str, Any] = {}
        if isinstance(box, h5py.Group):
            for part, dims in (("edges", (2, 3)), ("pygran_bounds", (3, 3)), ("pygran_tilt", (2, 2))):
                if isinstance(box.get(part), h5py.Group):
                    self._box_parts[part] = self._dataset(box[part], "value", *dims)
                    self._factors[part] = self._si(part, self._box_parts[part])
                    lengths.append(len(self._box_parts[part]))
        self._n = min(lengths)
        self._check_clock()
        self._boundary = self._boundary_of(box)

    def _check_element(self, name: str, dataset: Any, timed: bool) -> None:
        """Refuse an element whose rows, components, type or storage do not fit the others."""
        shape = dataset.shape[1:] if timed else dataset.shape
        rows = self._rows
        if rows is not None and shape[0] != rows:
            raise self._fail(
                f"{dataset.name} holds {shape[0]} particles per frame, but {self._rows_from} holds {rows}"
            )
        self._rows, self._rows_from = shape[0], dataset.name
        if name in VECTORS and shape[1:] != (3,):
            raise self._fail(
                f"{dataset.name} has shape {dataset.shape}: {name} needs 3 components per particle"
            )
        if name in INTEGER_ELEMENTS and dataset.dtype.kind not in "iu":
            raise self._fail(f"{dataset.name} holds {dataset.dtype}: {name} must be integers")
        declared = int(np.prod(shape, dtype=np.int64))
        frames = dataset.shape[0] if timed else 1  # a series without frames stores nothing, rightly
        if declared and frames and stored_elements(dataset) < declared:
            raise self._fail(
                f"{dataset.name} declares {shape[0]} particles but stores data for fewer than one frame "
                f"of them ({stored_elements(dataset)} of {declared} values): a sparse shell"
            )

    def _box(self, part: str, index: int) -> np.ndarray:
        values = np.asarray(self._box_parts[part][index], dtype=np.float64)
        return values * self._factors[part] if self._factors[part] != 1 else values

    def contacts(self) -> Trajectory | None:
        """The contact records of this particle group stored in the same file, if any."""
        if f"contacts/{self.group}" not in self._file:
            return None
        return H5MDContacts([self.path], self.group)

    def _placement(self, index: int) -> tuple[int, _Placement]:
        """The particle count of frame ``index`` and where its particles are: the rows whose id
        is not the fill value (the first ``particle_number`` rows without ids), in the order in
        which they were written (``pygran_order``) or else in row order."""
        count = int(self._number[index]) if self._number is not None else None
        rows = None  # the rows lo to hi, unless they have gaps
        if self._ids is not None:
            ids = np.empty(self._ids.shape[1], dtype=self._ids.dtype)
            if len(ids):
                self._ids.read_direct(ids, np.s_[index])
            present = ids != self._ids.fillvalue
            del ids
            n = int(np.count_nonzero(present))
            if count is not None and count != n:
                raise self._fail(f"frame {index}: {count} particles counted, but {n} rows have an id")
            lo = int(present.argmax()) if n else 0
            hi = len(present) - int(present[::-1].argmax()) if n else 0
            rows = None if hi - lo == n else lo + np.flatnonzero(present[lo:hi])
        else:
            held = self._rows or 0
            n = held if count is None else count
            if not 0 <= n <= held:
                raise self._fail(f"frame {index}: {n} particles, but the elements hold {held}")
            lo, hi = 0, n
        order = None
        if self._order is not None and n:
            order = np.empty(hi - lo, dtype=self._order.dtype)
            self._order.read_direct(order, np.s_[index, lo:hi])
            order = order if rows is None else order[rows - lo]
            ordered = bool((order[1:] > order[:-1]).all())
            if not (order[0] == 0 and order[-1] == n - 1 if ordered else _permutes(order)):
                raise self._fail(f"frame {index}: {self._order.name} is not an order of its {n} particles")
            order = None if ordered else order
        if rows is None:  # row lo + i holds the particle order[i]
            return n, _Placement(lo, hi, order)
        return n, _Placement.of(rows, order)

    def _read_ahead(self, index: int, place: _Placement) -> None:
        """Ask the operating system to read the chunks of frame ``index`` from disk ahead of
        the reads, element by element: a chunk read alone waits for the disk once per chunk.
        Only where an element's chunks of the frame lie together in the file (as written here)."""
        try:
            handle = self._file.id.get_vfd_handle()
        except (OSError, RuntimeError, ValueError):
            return
        if not hasattr(os, "posix_fadvise") or not isinstance(handle, int) or place.hi == place.lo:
            return
        for _, dataset, timed in self._elements:
            if not timed or dataset.chunks is None:
                continue
            rows, corner = dataset.chunks[1], (0,) * (dataset.ndim - 2)
            first, last = (
                dataset.id.get_chunk_info_by_coord((index, r - r % rows, *corner))
                for r in (place.lo, place.hi - 1)
            )
            if first.byte_offset is None or last.byte_offset is None:
                continue
            start, stop = first.byte_offset, last.byte_offset + last.size
            size = dataset.dtype.itemsize * (place.hi - place.lo + rows) * int(np.prod(dataset.shape[2:]))
            if 0 < stop - start <= 2 * size:
                os.posix_fadvise(handle, start, stop - start, os.POSIX_FADV_WILLNEED)

    def _frame(self, index: int) -> Frame:
        n, place = self._placement(index)
        self._read_ahead(index, place)
        arrays: dict[str, np.ndarray] = {}
        for name, dataset, timed in self._elements:
            columns = _read_rows(dataset, index if timed else None, place, n)
            if self._factors[name] != 1:
                for column in columns:
                    column *= self._factors[name]
            if name in VECTORS:
                arrays.update(zip(VECTORS[name], columns))
            elif dataset.ndim == 2 + timed:
                arrays.update({f"{name}[{j + 1}]": column for j, column in enumerate(columns)})
            else:
                arrays["type" if name == "species" else name] = columns[0]
        problem = particle_problem(arrays)
        if problem:
            raise self._fail(f"frame {index}: {problem}")
        box, attrs = None, {}
        if "pygran_bounds" in self._box_parts:
            box = self._box("pygran_bounds", index).reshape(3, 2)
        elif "edges" in self._box_parts:
            edges = self._box("edges", index)
            lengths = np.diag(edges.reshape(3, 3)) if edges.size == 9 else edges.reshape(3)
            box = np.column_stack([np.zeros(3), lengths])
        if box is not None and np.isnan(box).all():
            box = None
        if "pygran_tilt" in self._box_parts:
            attrs["tilt"] = self._box("pygran_tilt", index).reshape(3)
        return Frame(
            arrays,
            timestep=int(self._step[index]),
            time=self._time_at(index),
            box=box,
            boundary=self._boundary,
            attrs=attrs,
        )


def _text(value: Any) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)
