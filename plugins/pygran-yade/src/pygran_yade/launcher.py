"""Finding the YADE launcher without searching the disk."""

from __future__ import annotations

import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from pygran_core.errors import EngineError

LAUNCHER_ENV = "PYGRAN_YADE"


def find_launcher() -> str:
    """Path of the YADE launcher: ``$PYGRAN_YADE``, else ``yade`` on ``PATH``.

    Raises :class:`EngineError` saying how to install YADE when neither has it.
    """
    explicit = os.environ.get(LAUNCHER_ENV)
    if explicit:
        if not (Path(explicit).is_file() and os.access(explicit, os.X_OK)):
            raise EngineError(f"{LAUNCHER_ENV}={explicit!r} is not an executable YADE launcher")
        return explicit
    found = shutil.which("yade")
    if found is None:
        raise EngineError(
            "YADE is not installed (no `yade` on PATH). On Debian/Ubuntu: `apt-get install -y yade`; "
            f"or set {LAUNCHER_ENV} to the launcher's path."
        )
    return found


@dataclass(frozen=True)
class Interpreter:
    """The Python that runs YADE, and the directory its ``yade`` package lives in."""

    python: str
    pythonpath: str


def interpreter(launcher: str) -> Interpreter:
    """Read the interpreter (``#!`` line) and YADE's ``py`` directory (the launcher's
    ``sys.path.insert(1, '...')``) from the launcher script itself."""
    try:
        text = Path(launcher).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise EngineError(f"Cannot read the YADE launcher {launcher}: {exc}") from exc
    shebang = text.splitlines()[0] if text else ""
    found = re.search(r"sys\.path\.insert\(\s*1\s*,\s*['\"]([^'\"]+)['\"]\s*\)", text)
    if not shebang.startswith("#!") or found is None:
        raise EngineError(
            f"{launcher} is not a YADE launcher script (expected a '#!' Python line and "
            "sys.path.insert(1, '<yade>/py')); point PYGRAN_YADE at YADE's `yade` launcher"
        )
    python = shebang[2:].split()
    if Path(python[0]).name == "env":
        python = python[1:]
    return Interpreter(python=python[0], pythonpath=found.group(1))
