"""Type stub of the compiled module ``_accel`` (see _accel.pyx)."""

from typing import Any

import numpy as np

def histogram(cells: Any, squared: np.ndarray, reference: np.ndarray | None) -> np.ndarray: ...
def pair_keys(cells: Any) -> np.ndarray: ...
def cell_order(cell: np.ndarray, start: np.ndarray) -> np.ndarray: ...
def parse_table(text: Any, ncols: int, nrows: int) -> np.ndarray | None: ...
def cg_points(
    axes: np.ndarray,
    lower: np.ndarray,
    spacing: np.ndarray,
    n: np.ndarray,
    wrap: np.ndarray,
    kernel: int,
    width: float,
    cutoff: float,
    positions: np.ndarray,
    values: np.ndarray,
    order: np.ndarray,
) -> np.ndarray: ...
def cg_segments(
    axes: np.ndarray,
    lower: np.ndarray,
    spacing: np.ndarray,
    n: np.ndarray,
    wrap: np.ndarray,
    kernel: int,
    width: float,
    cutoff: float,
    start: np.ndarray,
    branch: np.ndarray,
    values: np.ndarray,
    order: np.ndarray,
    nodes: np.ndarray,
    weights: np.ndarray,
    piece: float,
) -> np.ndarray: ...
