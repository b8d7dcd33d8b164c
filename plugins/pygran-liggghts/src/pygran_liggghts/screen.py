"""LIGGGHTS' screen output written line by line, on every rank, so that no error message is lost.

LIGGGHTS writes its screen (``-screen FILE``) through a C ``FILE`` that buffers: an error
through ``error->one`` (``MPI_Abort``) ends the process before the buffer reaches the file,
and only rank 0 has a screen at all, so an ``error->one`` on another rank prints nothing.
:func:`capture_screen` gives every rank a line-buffered screen of ours
(``fopencookie``, glibc): rank 0 appends to the ``-screen`` file, rank k > 0 to
``<stem>.rank<k><suffix>`` (created on its first line), and with ``echo`` each ``ERROR``
line is also written to standard error, for the console of a script run under ``mpirun``
(rank k > 0 waits a second first: when every rank fails alike, rank 0's abort ends it before
it prints the same line again).

The ``screen`` member of the LIGGGHTS instance is found by value: rank 0 finds the stream
LIGGGHTS opened for the ``-screen`` file among glibc's open streams (``_IO_list_all``) and
looks for that pointer in the first words of the instance; every rank of one binary has the
same layout. Where any of this is unavailable, the screen is left as LIGGGHTS made it.

:func:`insertion_events` reads what LIGGGHTS' insertion fixes write on that screen (how many
each event inserted, and whether fewer than it asked for).

This module imports nothing of ``pygran_core`` (the worker loads it).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

#: glibc's ``struct _IO_FILE`` on LP64: offset of ``_chain``, the next open stream.
_CHAIN_OFFSET = 104
#: Words of the LIGGGHTS instance searched for its ``screen`` member (it is the 17th).
_SEARCHED_WORDS = 64
_IOLBF = 1
#: Seconds a rank other than 0 waits before echoing an error line (see the module docstring).
ECHO_DELAY = 1.0

_WRITE = ctypes.CFUNCTYPE(ctypes.c_ssize_t, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)
_CLOSE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p)


class _CookieFunctions(ctypes.Structure):
    _fields_ = [("read", ctypes.c_void_p), ("write", _WRITE), ("seek", ctypes.c_void_p), ("close", _CLOSE)]


#: ``fix insert/*``'s line after each insertion event (rank 0's screen).
_INSERTED = re.compile(r"INFO: Particle insertion (\S+): inserted (\d+) particle templates .* at step (\d+)")
#: ... its warning right after it when fewer were inserted than the event asked for.
_SHORT = "Less insertions than requested"
#: ... and, as an insertion by rate starts, the particles it asks for at each event.
_PER_EVENT = re.compile(r"INFO: Particle insertion (\S+): ([0-9.eE+-]+) particles every (\d+) steps")


@dataclass
class InsertionEvent:
    """One insertion event of LIGGGHTS fix ``fix`` as its screen reports it."""

    fix: str
    step: int
    inserted: int
    short: bool = False  # fewer than asked for (LIGGGHTS: 'Less insertions than requested')


def insertion_events(text: str) -> tuple[list[InsertionEvent], dict[str, float]]:
    """The insertion events in LIGGGHTS screen output ``text`` and, by fix, the particles an
    insertion by rate asks for per event (LIGGGHTS draws ``int(per + uniform)`` each time)."""
    events: list[InsertionEvent] = []
    per_event: dict[str, float] = {}
    for line in text.splitlines():
        if (match := _INSERTED.search(line)) is not None:
            events.append(InsertionEvent(match[1], int(match[3]), int(match[2])))
        elif _SHORT in line and events:
            events[-1].short = True
        elif (match := _PER_EVENT.search(line)) is not None:
            per_event[match[1]] = float(match[2])
    return events, per_event


def rank_log(path: Path, rank: int) -> Path:
    """The screen file of rank ``rank`` (``path`` itself for rank 0)."""
    return path if rank == 0 else path.with_name(f"{path.stem}.rank{rank}{path.suffix}")


class Screen:
    """One rank's screen: lines to its file and, with ``echo``, error lines to standard error.

    Keep it alive as long as the LIGGGHTS instance: its C callbacks live here.
    """

    def __init__(self, path: Path, rank: int, echo: str | None) -> None:
        self.path, self.rank, self.echo = rank_log(path, rank), rank, echo
        self._file: BinaryIO | None = None
        self.functions = _CookieFunctions(None, _WRITE(self._write), None, _CLOSE(self._close))

    def _write(self, _cookie: Any, data: int, size: int) -> int:
        try:
            text = ctypes.string_at(data, size)
            if self._file is None:
                self._file = self.path.open("ab", buffering=0)
            self._file.write(text)
            if self.echo is not None:
                errors = [line for line in text.splitlines() if line.startswith(b"ERROR")]
                if errors and self.rank > 0:
                    time.sleep(ECHO_DELAY)
                for line in errors:
                    sys.stderr.write(f"{self.echo}: {line.decode(errors='replace')} (log: {self.path})\n")
                    sys.stderr.flush()
        except Exception:  # noqa: BLE001 - a failing callback must not take LIGGGHTS down
            pass
        return size

    def _close(self, _cookie: Any) -> int:
        if self._file is not None:
            self._file.close()
        return 0


def _libc() -> ctypes.CDLL | None:
    libc = ctypes.CDLL(None)
    if not all(hasattr(libc, name) for name in ("fopencookie", "_IO_list_all", "setvbuf")):
        return None
    libc.fopencookie.argtypes = [ctypes.c_void_p, ctypes.c_char_p, _CookieFunctions]
    libc.fopencookie.restype = ctypes.c_void_p
    libc.setvbuf.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_size_t]
    libc.fileno.argtypes = [ctypes.c_void_p]
    libc.fflush.argtypes = [ctypes.c_void_p]
    return libc


def _stream_of(libc: ctypes.CDLL, path: Path) -> int | None:
    """The open C stream writing to ``path``, if any."""
    with contextlib.suppress(OSError):
        target = os.stat(path)
        stream = ctypes.c_void_p.in_dll(libc, "_IO_list_all").value
        while stream:
            fd = libc.fileno(stream)
            if fd >= 0:
                status = os.fstat(fd)
                if (status.st_dev, status.st_ino) == (target.st_dev, target.st_ino):
                    return stream
            stream = ctypes.c_void_p.from_address(stream + _CHAIN_OFFSET).value
    return None


def capture_screen(instance: int, comm: Any, path: Path, echo: str | None) -> Screen | None:
    """Give every rank of ``comm`` a line-buffered screen of ours (see the module docstring).

    ``instance`` is the LIGGGHTS handle; ``path`` the ``-screen`` file rank 0 has open.
    Collective; returns this rank's :class:`Screen`, or ``None`` where it cannot be done.
    """
    libc = _libc()
    offset = None
    if comm.rank == 0 and libc is not None:
        stream = _stream_of(libc, path)
        words = [ctypes.c_void_p.from_address(instance + 8 * i).value for i in range(_SEARCHED_WORDS)]
        if stream is not None and words.count(stream) == 1:
            offset = 8 * words.index(stream)
            libc.fflush(stream)  # what LIGGGHTS wrote so far; the stream stays open, unused
    offset = comm.bcast(offset, root=0)
    if offset is None or libc is None:
        return None
    member = ctypes.c_void_p.from_address(instance + offset)
    if comm.rank > 0 and member.value is not None:
        return None  # not the empty screen expected: leave it
    screen = Screen(path, comm.rank, echo)
    stream = libc.fopencookie(None, b"w", screen.functions)
    if not stream:
        return None
    libc.setvbuf(stream, None, _IOLBF, 0)
    member.value = stream
    return screen
