"""What the parts of the native solver share: its state and the checks of particles' types,
positions and ids (see :class:`pygran_native.solver.Solver`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from pygran_core.errors import ConfigError
from pygran_native._solver import Core
from pygran_native.arguments import array_of


class SolverBase:
    """The state of a :class:`~pygran_native.solver.Solver` that its parts (walls, bodies,
    checkpoints) use, and the checks they share."""

    box: np.ndarray
    periodic: tuple[bool, ...]
    threads: int
    rng: np.random.Generator
    _core: Core
    #: the contact model's settings (see contact_model.model_tables), None before there is one
    _model: dict[str, Any] | None
    _viscous: np.ndarray
    _next_id: int
    _next_body: int
    _next_wall: int
    _next_vertex: int
    #: wall handle -> "plane", "cylinder" or "mesh"
    _walls: dict[int, str]

    @property
    def ntypes(self) -> int:
        """Number of material types of the contact model (0 before :meth:`set_contact_model`)."""
        return 0 if self._model is None else self._model["youngs"].shape[0]

    def _check_types(self, types: np.ndarray, name: str) -> None:
        if self._model is None:
            raise ConfigError(f"{name}: call set_contact_model before adding particles or walls.")
        if types.size and (types.min() < 0 or types.max() >= self.ntypes):
            raise ConfigError(
                f"{name}: types must lie in [0, {self.ntypes - 1}], got {types.min()}..{types.max()}."
            )

    def _check_inside(self, x: np.ndarray, name: str) -> None:
        for d in range(3):
            if not self.periodic[d] and np.any((x[:, d] < self.box[0, d]) | (x[:, d] > self.box[1, d])):
                raise ConfigError(f"{name}: outside the fixed boundary of axis {'xyz'[d]}.")

    def _index(self, ids, name: str) -> np.ndarray:
        """Storage indices of the particles with these ids (ConfigError for unknown ids)."""
        ids = array_of(np.atleast_1d(ids), name, (-1,), np.int64)
        stored = self._core.array("id")
        order = np.argsort(stored)
        pos = np.searchsorted(stored[order], ids)
        pos = np.minimum(pos, max(len(stored) - 1, 0))
        if len(stored) == 0 or np.any(stored[order][pos] != ids):
            raise ConfigError(f"{name}: unknown particle id(s) {np.setdiff1d(ids, stored).tolist()}.")
        return np.ascontiguousarray(order[pos], dtype=np.int32)

    def _free(self, ids, name: str) -> np.ndarray:
        """Storage indices of the particles with these ids, none a clump's sphere."""
        index = self._index(ids, name)
        body = self._core.array("body")[index]
        if np.any(body >= 0):
            raise ConfigError(
                f"{name}: particle(s) {self._core.array('id')[index[body >= 0]].tolist()} are spheres of "
                "clumps, which move and grow with their clump only."
            )
        return index
