"""Typed ctypes binding of the LIGGGHTS C library interface (``/usr/include/liggghts/library.h``).

Every C signature is declared once, in :func:`_declare`. :class:`Liggghts` is one LIGGGHTS
instance on an mpi4py communicator: commands in, per-atom arrays out as numpy arrays
gathered over the ranks and ordered by atom id (no per-atom Python loops).
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from pygran_liggghts.library import find_library, load_addon
from pygran_liggghts.screen import capture_screen

#: PyGran quantity -> (LIGGGHTS per-atom array, columns, ctypes element type).
ATOM_ARRAYS: dict[str, tuple[str, int, Any]] = {
    "x": ("x", 3, ctypes.c_double),
    "v": ("v", 3, ctypes.c_double),
    "f": ("f", 3, ctypes.c_double),
    "omega": ("omega", 3, ctypes.c_double),
    "torque": ("torque", 3, ctypes.c_double),
    "radius": ("radius", 1, ctypes.c_double),
    "mass": ("rmass", 1, ctypes.c_double),
    "id": ("id", 1, ctypes.c_int),
    "type": ("type", 1, ctypes.c_int),
    "mol": ("molecule", 1, ctypes.c_int),  # the body of each sphere (with fix multisphere)
}


def _declare(lib: ctypes.CDLL, comm_type: type) -> ctypes.CDLL:
    """Declare argument and result types of the ``library.h`` functions PyGran calls."""
    handle, text, pointer = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p
    signatures: dict[str, tuple[list[Any], Any]] = {
        "lammps_open": (
            [ctypes.c_int, ctypes.POINTER(ctypes.c_char_p), comm_type, ctypes.POINTER(handle)],
            None,
        ),
        "lammps_close": ([handle], None),
        "lammps_command": ([handle, text], pointer),
        "lammps_extract_global": ([handle, text], pointer),
        "lammps_extract_atom": ([handle, text], pointer),
        "lammps_extract_compute": ([handle, text, ctypes.c_int, ctypes.c_int], pointer),
        "lammps_extract_fix": (
            [handle, text, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_int],
            pointer,
        ),
        "lammps_free": ([pointer], None),
    }
    for name, (argtypes, restype) in signatures.items():
        function = getattr(lib, name)
        function.argtypes, function.restype = argtypes, restype
    return lib


def _comm_type() -> type[ctypes.c_int] | type[ctypes.c_void_p]:
    """The C type of ``MPI_Comm`` in the MPI library mpi4py runs on (int or pointer)."""
    from mpi4py import MPI

    return ctypes.c_int if MPI._sizeof(MPI.Comm) == ctypes.sizeof(ctypes.c_int) else ctypes.c_void_p


@cache
def load() -> ctypes.CDLL:
    """libliggghts with its signatures declared, and PyGran's add-on to it when built (each
    loaded once per process, before any LIGGGHTS instance reads a ``pair_style``)."""
    lib = _declare(ctypes.CDLL(find_library(), mode=ctypes.RTLD_GLOBAL), _comm_type())
    load_addon()
    return lib


class Liggghts:
    """One LIGGGHTS instance on the mpi4py communicator ``comm``; every rank of ``comm``
    makes the same calls in the same order (SPMD), as LIGGGHTS requires.

    ``args`` are command-line arguments (``-screen``, ``-log``, ...). Any LIGGGHTS error ends
    the process (LIGGGHTS calls ``exit``); run it in a worker to survive that. With a
    ``-screen`` file, every rank's screen is line-buffered (:func:`~.screen.capture_screen`),
    so the message of an error is in the file (or rank file) when the process ends; ``echo``
    also writes error lines to standard error, prefixed with it.
    """

    def __init__(self, args: Sequence[str], comm: Any, echo: str | None = None) -> None:
        from mpi4py import MPI

        self.comm = comm
        self._lib = load()
        argv = [b"liggghts", *(a.encode() for a in args)]
        c_argv = (ctypes.c_char_p * len(argv))(*argv)
        comm_type = _comm_type()
        c_comm = comm_type.from_address(MPI._addressof(comm))
        self._handle = ctypes.c_void_p()
        self._lib.lammps_open(len(argv), c_argv, c_comm, ctypes.byref(self._handle))
        if self._handle.value is None:
            raise RuntimeError(f"lammps_open made no LIGGGHTS instance (arguments {list(args)})")
        instance = self._handle.value
        self._screen = None
        if "-screen" in args and args[args.index("-screen") + 1] != "none":
            path = Path(args[args.index("-screen") + 1])
            self._screen = capture_screen(instance, comm, path, echo)

    def command(self, line: str) -> None:
        """Execute one input line."""
        self._lib.lammps_command(self._handle, line.encode())

    def timestep(self) -> int:
        """The current step number."""
        pointer = self._lib.lammps_extract_global(self._handle, b"ntimestep")
        return int(ctypes.cast(pointer, ctypes.POINTER(ctypes.c_int64))[0])

    def _nlocal(self) -> int:
        pointer = self._lib.lammps_extract_global(self._handle, b"nlocal")
        return ctypes.cast(pointer, ctypes.POINTER(ctypes.c_int))[0]

    def _view(self, quantity: str) -> np.ndarray:
        """This rank's per-atom array ``quantity`` (see :data:`ATOM_ARRAYS`) in place."""
        name, columns, ctype = ATOM_ARRAYS[quantity]
        count = self._nlocal()
        pointer = self._lib.lammps_extract_atom(self._handle, name.encode())
        if not pointer or count == 0:
            return np.empty((0, columns) if columns > 1 else 0, np.dtype(ctype))
        if columns > 1:  # double **: row pointers into one contiguous block
            pointer = ctypes.cast(pointer, ctypes.POINTER(ctypes.POINTER(ctype)))[0]
            return np.ctypeslib.as_array(pointer, shape=(count, columns))
        return np.ctypeslib.as_array(ctypes.cast(pointer, ctypes.POINTER(ctype)), shape=(count,))

    def local(self, quantity: str) -> np.ndarray:
        """A copy of this rank's per-atom array ``quantity`` (see :data:`ATOM_ARRAYS`)."""
        return self._view(quantity).copy()

    def assign(self, quantity: str, ids: np.ndarray, value: Sequence[float]) -> None:
        """Set ``quantity`` of the atoms with these ids to ``value``, in LIGGGHTS' own arrays
        (the next ``run`` must do its full set-up, which sends them to the ghost atoms)."""
        view = self._view(quantity)
        view[np.isin(self._view("id"), ids)] = value

    def gather(self, quantities: Sequence[str], root: int | None = 0) -> dict[str, np.ndarray] | None:
        """Per-atom arrays of all ranks ordered by atom id, on rank ``root`` (``None``: on all).

        Other ranks get ``None`` when ``root`` is a rank.
        """
        mine = [self.local(q) for q in ("id", *quantities)]
        parts = self.comm.allgather(mine) if root is None else self.comm.gather(mine, root=root)
        if parts is None:
            return None
        arrays = [np.concatenate([p[i] for p in parts]) for i in range(len(mine))]
        order = np.argsort(arrays[0], kind="stable")
        return {q: a[order] for q, a in zip(quantities, arrays[1:])}

    def max_id(self) -> int:
        """The largest atom id over all ranks (0 without atoms)."""
        tags = self.local("id")
        return int(self.comm.allreduce(int(tags.max()) if tags.size else 0, op=_max()))

    def count(self) -> int:
        """Number of atoms over all ranks, counted now (LIGGGHTS' own count is updated only
        when it prints thermodynamic output)."""
        return int(self.comm.allreduce(self._nlocal()))

    def inserted(self, fixes: Sequence[str]) -> int:
        """Particles inserted so far by the insertion fixes ``fixes`` (element 0 of their global
        vector; a fix that does not exist counts 0)."""
        total = 0
        for fix in fixes:
            pointer = self._lib.lammps_extract_fix(self._handle, fix.encode(), 0, 1, 0, 0)
            if pointer:
                total += int(ctypes.cast(pointer, ctypes.POINTER(ctypes.c_double))[0])
                self._lib.lammps_free(pointer)
        return total

    def fix_vector(self, fix: str, count: int) -> list[float]:
        """The first ``count`` elements of fix ``fix``'s global vector (evaluated now)."""
        values = []
        for index in range(count):
            pointer = self._lib.lammps_extract_fix(self._handle, fix.encode(), 0, 1, index, 0)
            if not pointer:
                raise KeyError(f"LIGGGHTS has no fix {fix!r} with a global vector")
            values.append(float(ctypes.cast(pointer, ctypes.POINTER(ctypes.c_double))[0]))
            self._lib.lammps_free(pointer)
        return values

    def compute_scalar(self, compute: str) -> float:
        """The global scalar of compute ``compute`` (evaluated now)."""
        pointer = self._lib.lammps_extract_compute(self._handle, compute.encode(), 0, 0)
        if not pointer:
            raise KeyError(f"LIGGGHTS has no compute {compute!r} with a global scalar")
        return float(ctypes.cast(pointer, ctypes.POINTER(ctypes.c_double))[0])

    def close(self) -> None:
        """Delete the instance (MPI stays initialised; mpi4py finalises it at exit)."""
        if self._handle:
            self._lib.lammps_close(self._handle)  # closes the screen too
            self._handle = ctypes.c_void_p()
            self._screen = None

    def __enter__(self) -> Liggghts:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _max() -> Any:
    from mpi4py import MPI

    return MPI.MAX
