"""Checks of the native solver's arguments: numbers as arrays of the expected shape, without a
copy when they are one already (the compiled core copies what it keeps)."""

from __future__ import annotations

from collections.abc import Mapping
from types import SimpleNamespace

import numpy as np

from pygran_core.errors import ConfigError


def layout(fields: Mapping[str, tuple[int, int]]) -> SimpleNamespace:
    """Indices into a row of values by name: the first value's, or a slice of several."""
    return SimpleNamespace(
        **{k: first if n == 1 else slice(first, first + n) for k, (first, n) in fields.items()}
    )


def array_of(value, name: str, shape: tuple, dtype=float) -> np.ndarray:
    """``value`` as a C-contiguous array of ``shape`` (-1 = any length), or a ConfigError naming
    it: ``value`` itself when it is one (not to be changed in place)."""
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name}: expected numbers, got {value!r}.") from exc
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        want = "x".join("n" if s == -1 else str(s) for s in shape) or "a scalar"
        raise ConfigError(f"{name}: expected shape ({want}), got {arr.shape}.")
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ConfigError(f"{name}: values must be finite.")
    return arr if arr.flags.c_contiguous else np.ascontiguousarray(arr)


def per_particle(value, name: str, n: int, dtype=float) -> np.ndarray:
    """``value`` (one per particle, or one for all) as n values."""
    if np.ndim(value) == 0:
        value = np.full(n, array_of(value, name, (), dtype), dtype=dtype)
    return array_of(value, name, (n,), dtype)


def vectors_of(value, name: str, n: int) -> np.ndarray:
    """``value`` (a vector per particle, or one for all, None for zeros) as an (n, 3) array: one
    for all is a read-only view that repeats it, without a copy per particle."""
    if value is None:
        value = (0.0, 0.0, 0.0)
    if np.ndim(value) == 1:
        return np.broadcast_to(array_of(value, name, (3,)), (n, 3))
    return array_of(value, name, (n, 3))
