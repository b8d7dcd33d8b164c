"""Finding the LIGGGHTS shared library without searching the disk."""

from __future__ import annotations

import ctypes.util
import os
from pathlib import Path

LIBRARY_ENV = "PYGRAN_LIGGGHTS_LIB"
INSTALL = "apt-get install -y liggghts libliggghts-dev openmpi-bin libopenmpi-dev"


def find_library() -> str:
    """Path or loader name of libliggghts: ``$PYGRAN_LIGGGHTS_LIB``, else the dynamic loader.

    Raises :class:`EngineError` saying how to install LIGGGHTS when neither has it. (The
    LIGGGHTS worker imports this module: ``pygran_core`` is imported only on an error.)
    """
    explicit = os.environ.get(LIBRARY_ENV)
    if explicit:
        if not Path(explicit).is_file():
            raise _error(f"{LIBRARY_ENV}={explicit!r} is not a file; point it at libliggghts.so")
        return explicit
    found = ctypes.util.find_library("liggghts")
    if found is None:
        raise _error(
            "The LIGGGHTS shared library (libliggghts.so) is not installed. On Debian/Ubuntu: "
            f"`{INSTALL}`; or build LIGGGHTS as a shared library and set {LIBRARY_ENV} to its path."
        )
    return found


def _error(message: str) -> Exception:
    from pygran_core.errors import EngineError

    return EngineError(message)
