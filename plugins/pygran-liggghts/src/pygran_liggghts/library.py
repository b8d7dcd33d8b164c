"""Finding the LIGGGHTS shared library without searching the disk, and PyGran's add-on to it."""

from __future__ import annotations

import ctypes.util
import json
import logging
import os
import subprocess
import sys
from dataclasses import dataclass
from functools import cache
from pathlib import Path

LIBRARY_ENV = "PYGRAN_LIGGGHTS_LIB"
INSTALL = "apt-get install -y liggghts libliggghts-dev openmpi-bin libopenmpi-dev"
#: LIGGGHTS' ``gran model`` name of the Thornton-Ning add-on (``addon/``, built by ``setup.py``).
ADDON_MODEL = "thornton_ning_pygran"
#: The capabilities the add-on gives the engine.
ADDON_CAPABILITIES = frozenset({"thornton-ning"})
REINSTALL = "apt-get install -y libliggghts-dev, then pip install --force-reinstall --no-deps pygran-liggghts"
#: Python code that loads the add-on and prints, as JSON, why it is unavailable (``""``: it loaded).
PROBE = "import json; from pygran_liggghts.library import _load_addon; print(json.dumps(_load_addon()))"
#: Seconds the probe process may take.
PROBE_TIMEOUT = 120.0


def _library_or_none() -> str | None:
    """``$PYGRAN_LIGGGHTS_LIB`` if it is a file, else what the dynamic loader finds, or None."""
    explicit = os.environ.get(LIBRARY_ENV)
    if explicit:
        return explicit if Path(explicit).is_file() else None
    return ctypes.util.find_library("liggghts")


def find_library() -> str:
    """Path or loader name of libliggghts: ``$PYGRAN_LIGGGHTS_LIB``, else the dynamic loader.

    Raises :class:`EngineError` saying how to install LIGGGHTS when neither has it. (The
    LIGGGHTS worker imports this module: ``pygran_core`` is imported only on an error.)
    """
    explicit = os.environ.get(LIBRARY_ENV)
    if explicit and not Path(explicit).is_file():
        raise _error(f"{LIBRARY_ENV}={explicit!r} is not a file; point it at libliggghts.so")
    found = _library_or_none()
    if found is None:
        raise _error(
            "The LIGGGHTS shared library (libliggghts.so) is not installed. On Debian/Ubuntu: "
            f"`{INSTALL}`; or build LIGGGHTS as a shared library and set {LIBRARY_ENV} to its path."
        )
    return found


def _error(message: str) -> Exception:
    from pygran_core.errors import EngineError

    return EngineError(message)


@dataclass(frozen=True)
class Addon:
    """Whether the Thornton-Ning add-on loads, and if not, why."""

    loaded: bool
    reason: str = ""


@cache
def load_addon() -> Addon:
    """Load libliggghts, then the add-on, both with ``RTLD_GLOBAL`` (once per process).

    Its static initializer registers ``thornton_ning_pygran`` with LIGGGHTS' contact-model
    and granular-style factories, so it must be loaded before ``pair_style gran``. A failure
    is logged (logger ``pygran.liggghts``) and returned, never raised.
    """
    return _reported(_load_addon())


@cache
def probe_addon() -> Addon:
    """Whether the add-on loads, found by loading it in a child process (:data:`PROBE`, once per
    process), logged and returned as :func:`load_addon` does.

    For a process that runs LIGGGHTS in a worker: libliggghts, loaded into it, would bring
    the VTK libraries LIGGGHTS is linked to, on which pip's VTK crashes when a script then uses it.
    """
    try:
        done = subprocess.run(
            [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=PROBE_TIMEOUT
        )
    except subprocess.TimeoutExpired:
        return _reported(f"loading the add-on in a probe process took more than {PROBE_TIMEOUT:g} s")
    lines = done.stdout.splitlines()
    if done.returncode != 0 or not lines:
        return _reported(
            f"the probe process loading the add-on ({sys.executable} -c ...) ended with status "
            f"{done.returncode}: {done.stderr.strip()[-500:]}"
        )
    return _reported(json.loads(lines[-1]))


def _reported(reason: str) -> Addon:
    """The add-on's availability given why it does not load (``""``: it does), the reason logged."""
    if reason:
        logging.getLogger("pygran.liggghts").warning("ThorntonNing unavailable on LIGGGHTS: %s", reason)
    return Addon(not reason, reason)


def _load_addon() -> str:
    """Load the add-on; the reason it is unavailable, or ``""``."""
    found = sorted(Path(__file__).parent.glob("_thornton_ning*.so"))
    if not found:
        return (
            "the Thornton-Ning add-on to LIGGGHTS is not built (pip found no LIGGGHTS headers when "
            f"it installed pygran-liggghts): {REINSTALL}"
        )
    library = _library_or_none()
    if library is None:
        return f"no LIGGGHTS shared library (${LIBRARY_ENV} or the dynamic loader): {INSTALL}"
    try:
        liggghts = ctypes.CDLL(library, mode=ctypes.RTLD_GLOBAL)
        addon = ctypes.CDLL(str(found[0]), mode=ctypes.RTLD_GLOBAL)
    except OSError as exc:
        return f"the Thornton-Ning add-on {found[0].name} does not load ({exc}): {REINSTALL}"
    addon.pygran_thornton_ning_liggghts.restype = ctypes.c_void_p
    opener = getattr(liggghts, "lammps_open", None)
    if opener is None or addon.pygran_thornton_ning_liggghts() != ctypes.cast(opener, ctypes.c_void_p).value:
        return (
            f"the Thornton-Ning add-on is linked to another libliggghts than {library}: build it "
            f"against that library's headers and point the loader at it"
        )
    addon.pygran_thornton_ning_model.restype = ctypes.c_char_p
    name = addon.pygran_thornton_ning_model().decode()
    if name != ADDON_MODEL:
        return f"{found[0].name} registers the model {name!r}, not {ADDON_MODEL!r}: {REINSTALL}"
    return ""
