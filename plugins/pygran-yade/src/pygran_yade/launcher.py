"""Finding the YADE launcher without searching the disk."""

from __future__ import annotations

import os
import shutil
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
