"""HDF5 files as PyGran reads and writes them: the one place that opens an HDF5 file for
reading (H5MD trajectories, checkpoints), refusing any that reaches outside itself, and the
claim and space reservation of a file being written.

A file from elsewhere can name other files: an external link, external raw storage or a
virtual dataset makes HDF5 read ``/etc/passwd`` as if it were the file's own data. Every such
file is refused with a :class:`ReadError` before anything in it is read.

A writer claims its file (a ``fcntl`` lock, which HDF5's own ``flock`` does not touch)
before truncating it, so a second writer fails without destroying the first one's file, and
checks that the disk has room for a frame before HDF5 writes it: HDF5 running out of space in
the middle of a metadata write leaves a file it cannot reopen, and a library state that crashes
the interpreter at exit.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import functools
import os
import struct
from pathlib import Path
from typing import Any, ClassVar

from pygran_core.errors import PyGranError, ReadError, WriteError

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Metadata read attempts of an SWMR reader: HDF5 sleeps 1, 2, 4, ... ns between them, so
#: 20 bound the wait to about a millisecond (its default of 100 is forever).
SWMR_READ_ATTEMPTS = 20
#: Space reserved beyond a frame's raw bytes, for the metadata HDF5 writes with it.
METADATA_RESERVE = 1 << 20
#: What the operating system says when a write cannot get space.
_NO_SPACE = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)


def load_h5py() -> Any:
    """The h5py module, imported on first use so that ``import pygran_core`` does not load
    HDF5: every module that reads or writes HDF5 takes it from here."""
    try:
        import h5py
    except ImportError as exc:
        raise PyGranError(
            f"HDF5 files (H5MD trajectories, checkpoints) need h5py, which does not import: {exc}; "
            "install it with `pip install h5py`"
        ) from exc
    return h5py


def open_hdf5(path: Path) -> Any:
    """``path`` opened for reading with h5py, or a :class:`ReadError`; a file with external
    links, external storage or virtual datasets is refused (:func:`refuse_outside_references`).

    The file is opened without SWMR, which checks its superblock and its size. Only a file
    that a writer left marked open (a writer killed before closing it, or one still writing)
    is then opened in SWMR mode, with HDF5's metadata read attempts bounded: an SWMR reader
    otherwise retries a damaged block with ever longer sleeps, which hangs on a truncated
    or damaged file.
    """
    h5py = load_h5py()

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        if "already open for write" not in str(exc):
            raise ReadError(f"{path}: not a readable HDF5 file: {exc}") from exc
        f = _open_swmr(path)
    try:
        refuse_outside_references(f, path)
    except (OSError, RuntimeError, KeyError, ValueError) as exc:  # damaged metadata
        f.close()
        raise ReadError(f"{path}: not a readable HDF5 file: {exc}") from exc
    except BaseException:
        f.close()
        raise
    return f


def _open_swmr(path: Path) -> Any:
    h5py = load_h5py()

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


def refuse_outside_references(f: Any, path: Path) -> None:
    """Raise :class:`ReadError` if the open file ``f`` has an external or user-defined link, a
    dataset with external raw storage or a virtual dataset: anything that makes HDF5 read
    another file. Links are listed without being followed, so nothing outside is opened."""
    h5py = load_h5py()

    outside: list[str] = []

    def link(name: str, found: Any) -> None:
        if isinstance(found, h5py.ExternalLink):
            outside.append(f"/{name} is an external link to {found.filename}:{found.path}")
        elif not isinstance(found, (h5py.HardLink, h5py.SoftLink)):
            outside.append(f"/{name} is a user-defined link")

    f.visititems_links(link)
    if not outside:  # soft links are followed below: only once no link leads out of the file

        def dataset(name: str, item: Any) -> None:
            if not isinstance(item, h5py.Dataset):
                return
            if item.is_virtual:
                outside.append(f"/{name} is a virtual dataset (its data lives in other files)")
            elif item.id.get_create_plist().get_external_count():
                outside.append(f"/{name} keeps its data in external files {item.external}")

        f.visititems(dataset)
    if outside:
        raise ReadError(
            f"{path}: refused: the file reaches outside itself ({'; '.join(outside[:3])}); PyGran reads "
            "only self-contained HDF5 files (h5repack copies external data in, if the source is trusted)"
        )


def stored_elements(dataset: Any) -> int:
    """How many elements ``dataset`` has storage for: a dataset declared far larger than what
    is stored is a sparse shell whose every read gives fill values."""
    h5py = load_h5py()

    layout = dataset.id.get_create_plist().get_layout()
    if layout == h5py.h5d.CHUNKED:
        per_chunk = 1
        for size in dataset.chunks:
            per_chunk *= size
        return int(dataset.id.get_num_chunks()) * per_chunk
    if layout == h5py.h5d.COMPACT:
        return int(dataset.size)
    return int(dataset.id.get_storage_size()) // max(dataset.dtype.itemsize, 1)


def _lock(fd: int) -> None:
    """Take an exclusive lock on the whole file open as ``fd``, or raise OSError if another
    holds one. Linux: an open-file-description lock, held by this descriptor alone whatever else
    opens and closes the file (HDF5 does); elsewhere a POSIX record lock (per process, which
    lapses when the process closes any descriptor of the file)."""
    if hasattr(fcntl, "F_OFD_SETLK"):
        fcntl.fcntl(fd, fcntl.F_OFD_SETLK, struct.pack("hhqqi4x", fcntl.F_WRLCK, os.SEEK_SET, 0, 0, 0))
    else:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


class Claim:
    """A file this process writes: created if missing, never truncated before it is held.

    The claim is a lock on an open descriptor (:func:`_lock`), kept until :meth:`close`, and an
    entry in this process's own table, for platforms whose locks do not exclude the process that
    holds them. Neither HDF5's own lock (``flock``) nor its readers are hindered by it.
    :meth:`reserve` checks that the disk has room for the next writes before HDF5 makes them.
    """

    #: (device, inode) of the files this process holds.
    _held: ClassVar[set[tuple[int, int]]] = set()

    def __init__(self, path: Path) -> None:
        self.path = path
        self._key: tuple[int, int] | None = None
        try:
            self._fd: int | None = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise WriteError(f"{path}: cannot be created for writing: {exc.strerror}") from None
        status = os.fstat(self._fd)
        key = (status.st_dev, status.st_ino)
        try:
            if key in self._held:
                raise OSError(errno.EAGAIN, "held")
            _lock(self._fd)
        except OSError:
            self.close()
            raise WriteError(
                f"{path} is being written by another writer; give this one another file name "
                "or output folder, or wait for the other to finish"
            ) from None
        self._key = key
        self._held.add(key)

    def truncate(self) -> None:
        """Empty the file (held, so no other writer's file is lost)."""
        assert self._fd is not None
        os.ftruncate(self._fd, 0)

    def reserve(self, size: int) -> None:
        """Check that ``size`` bytes (plus room for metadata) can be added to the file, by
        allocating them and giving them back, or raise :class:`WriteError` naming the file; a
        file system that cannot allocate ahead is left to HDF5. The file keeps its size."""
        if self._fd is None:
            return
        end = os.fstat(self._fd).st_size
        try:
            os.posix_fallocate(self._fd, end, size + METADATA_RESERVE)
        except OSError as exc:
            if exc.errno in _NO_SPACE:
                raise WriteError(f"{self.path}: no space for the next frame ({exc.strerror})") from None
        finally:
            os.ftruncate(self._fd, end)

    def close(self) -> None:
        """Give the file up: unlock it and close the descriptor."""
        if self._key is not None:
            self._held.discard(self._key)
            self._key = None
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the lock
            self._fd = None


def no_space(exc: BaseException) -> bool:
    """Whether an h5py error ``exc`` comes from a write that found no space."""
    text = str(exc)
    return any(os.strerror(code) in text or f"errno = {code}," in text for code in _NO_SPACE)


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py runs on (found among the loaded libraries), for the one setting
    h5py does not expose, or None where it cannot be found."""
    load_h5py()  # loads the library

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
