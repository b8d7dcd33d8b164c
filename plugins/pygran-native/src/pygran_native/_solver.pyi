"""Type stub of the compiled module ``_solver`` (see _solver.pyx for the layout and rules)."""

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

MAX_THREADS: int
TEAM_HEURISTICS: bool
MOTION_VALUES: int
SLOT_VALUES: int
VIBRATION_VALUES: int
HARMONICS: int
SLOT_LAYOUT: dict[str, tuple[int, int]]
VIBRATION_LAYOUT: dict[str, tuple[int, int]]
LOST_PLACES: tuple[str, ...]
TIMERS: tuple[str, ...]

class Core:
    n: int
    cap: int
    nthreads: int
    hs: int
    model: int
    rolling: int
    roff: int
    ntypes: int
    dirty: int
    time: float
    skin: float
    step: int
    lost: int
    rebuilds: int
    grid: tuple[tuple[int, int, int], float, int]
    ne: int
    nslots: int
    nvib: int
    nbody: int
    def __init__(
        self,
        lo: Sequence[float] | np.ndarray,
        hi: Sequence[float] | np.ndarray,
        periodic: Sequence[bool],
        gravity: Sequence[float] | np.ndarray,
        skin: float,
        threads: int,
    ) -> None: ...
    def set_model(
        self,
        model: int,
        hs: int,
        rolling: int,
        limit: bool,
        E: np.ndarray,
        G: np.ndarray,
        mu: np.ndarray,
        mur: np.ndarray,
        damp: np.ndarray,
        coh: np.ndarray,
        py: np.ndarray,
        rdamp: np.ndarray,
        vchar: float,
    ) -> None: ...
    def set_recording(self, on: bool) -> None: ...
    @property
    def recording(self) -> bool: ...
    def set_viscous(self, gamma: np.ndarray) -> None: ...
    def add_particles(
        self,
        x: np.ndarray,
        r: np.ndarray,
        m: np.ndarray,
        typ: np.ndarray,
        v: np.ndarray,
        w: np.ndarray,
        first_id: int,
    ) -> None: ...
    def add_bodies(
        self,
        x: np.ndarray,
        v: np.ndarray,
        q: np.ndarray,
        p: np.ndarray,
        m: np.ndarray,
        inertia: np.ndarray,
        typ: np.ndarray,
        bids: np.ndarray,
        counts: np.ndarray,
        offsets: np.ndarray,
        r: np.ndarray,
        ids: np.ndarray,
    ) -> None: ...
    def bodies(self) -> dict[str, np.ndarray]: ...
    def mark_removed(self, mask: np.ndarray) -> None: ...
    def set_vectors(self, name: str, index: np.ndarray, values: np.ndarray) -> None: ...
    def set_radii(self, index: np.ndarray, r: np.ndarray, m: np.ndarray) -> None: ...
    def add_elements(
        self, kind: np.ndarray, etype: np.ndarray, wall: np.ndarray, geo: np.ndarray, vid: np.ndarray
    ) -> None: ...
    def remove_elements(self, wall: int) -> None: ...
    def set_motion(
        self,
        wall: int,
        vel: np.ndarray,
        omega: np.ndarray,
        origin: np.ndarray,
        amplitude: np.ndarray,
        period: float,
    ) -> None: ...
    def get_vibrations(self) -> np.ndarray: ...
    def set_vibrations(self, values: np.ndarray) -> None: ...
    def get_slots(self) -> np.ndarray: ...
    def set_slots(self, values: np.ndarray) -> None: ...
    def take_lost(self) -> tuple[np.ndarray, float]: ...
    def run(self, nsteps: int, dt: float) -> None: ...
    def array(self, name: str) -> np.ndarray: ...
    def by_id(self, name: str) -> np.ndarray: ...
    def largest_radius(self) -> float: ...
    def contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def contact_forces(self) -> dict[str, np.ndarray]: ...
    def timings(self) -> dict[str, Any]: ...
    def list_entries(self) -> tuple[int, int]: ...
    def memory(self) -> dict[str, int]: ...
    def elements(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...
    def get_state(self) -> dict[str, np.ndarray]: ...
    def set_state(self, state: Mapping[str, np.ndarray]) -> None: ...
