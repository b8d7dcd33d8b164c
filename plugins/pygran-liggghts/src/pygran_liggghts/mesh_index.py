"""The ``.pvd`` index of the mesh frames LIGGGHTS writes itself as ``traj mfile`` with ``*`` in
its name (a ``.vtk`` file per frame, ``*`` its step), each at the simulated time of its step,
as PyGran's VTK writer indexes its own files.
"""

from __future__ import annotations

import logging

from pygran_core.errors import PluginNotFound
from pygran_core.io import open_writer
from pygran_core.simulation.engine import Engine
from pygran_core.simulation.specs import given


class MeshIndex:
    """The index of ``engine``'s mesh frames, kept by the rank that writes files (``enabled``).
    LIGGGHTS writes the frame of the step a run starts at as it starts: a frame is indexed once
    its file is there. On resume the core has cut the index back to the checkpoint's step, and
    LIGGGHTS writes that step's frame (see :meth:`again`) and the later ones again."""

    def __init__(self, engine: Engine, enabled: bool) -> None:
        self._engine = engine
        #: Whether frames are indexed: on that rank, until PyGran's VTK writer is found missing
        self._enabled = enabled
        self._waiting: list[tuple[int, float]] = []  # (step, time) of frames not indexed yet

    def due(self, step: int, time: float) -> None:
        """LIGGGHTS writes a mesh frame at ``step`` (``time``): index it once it is there."""
        self.again(step, time)
        self.update()

    def again(self, step: int, time: float) -> None:
        """LIGGGHTS will write the frame of ``step``, where a resumed run starts, again: the
        index, resumed after the engine's state, takes it (or drops the copy) at the next
        :meth:`update`."""
        mfile = self._engine.spec.traj.mfile
        if self._enabled and mfile is not None and "*" in mfile.name:
            self._waiting.append((step, time))

    def update(self) -> None:
        """Index the frames waiting whose files LIGGGHTS has written."""
        engine = self._engine
        while self._waiting and self._enabled:
            path = given(engine.spec.traj.mfile, "traj mfile")
            step, time = self._waiting[0]
            file = path.with_name(path.name.replace("*", str(step)))
            if not file.is_file():
                return
            writer = engine.files.writers.get("meshes")
            if writer is None:
                try:
                    writer = engine.files.writers["meshes"] = open_writer(path)
                except PluginNotFound as exc:
                    engine.log("no .pvd index for %s: %s", path.name, exc, level=logging.WARNING)
                    self._enabled = False
                    self._waiting.clear()
                    return
            writer.index_file(file, step, time)  # type: ignore[attr-defined]
            self._waiting.pop(0)
