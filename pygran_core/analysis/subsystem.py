"""The :class:`SubSystem` base: a set of elements (particles, mesh cells) with named arrays.

A SubSystem maps attribute names to per-element numpy arrays of one length N (1-D, or
N x k for vectors such as mesh points) and holds scalar metadata (``timestep``, ``box``,
``units``, ...). Arrays are read-only to the user; the methods that change them
(:meth:`translate`, :meth:`scale`, :meth:`noise`) replace them explicitly. Slicing with an
int, a slice, an integer array or a boolean mask returns a new object of the same class.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np

from pygran_core.errors import did_you_mean

Selection = int | slice | Sequence[int] | np.ndarray


def _frozen(values: Any) -> np.ndarray:
    array = np.array(values, copy=True)
    array.setflags(write=False)
    return array


class SubSystem:
    """Named per-element arrays plus scalar metadata.

    ``SubSystem(x=[...], y=[...], timestep=100)`` builds one from arrays (anything with a
    length) and scalars; ``SubSystem(SubSystem=other)`` (or ``Particles(Particles=other)``,
    any class name of the object's hierarchy) copies another.
    """

    #: Attributes that :meth:`translate`, :meth:`scale` and :meth:`noise` act on by default.
    coordinate_keys: tuple[str, ...] = ("x", "y", "z")

    _fields: dict[str, np.ndarray]
    _meta: dict[str, Any]

    def __init__(self, **data: Any) -> None:
        source = self._copy_source(data)
        fields: dict[str, np.ndarray] = {}
        meta: dict[str, Any] = {}
        if source is not None:
            fields.update({k: _frozen(v) for k, v in source._fields.items()})
            meta.update(source._meta)
        for key, value in data.items():
            if np.ndim(value) >= 1 and key not in ("box", "boundary"):
                fields[key] = _frozen(value)
            else:
                meta[key] = value
        lengths = {key: len(value) for key, value in fields.items()}
        if len(set(lengths.values())) > 1:
            raise ValueError(f"{type(self).__name__} attributes have different lengths: {lengths}")
        object.__setattr__(self, "_fields", fields)
        object.__setattr__(self, "_meta", meta)

    def _copy_source(self, data: dict[str, Any]) -> SubSystem | None:
        """Pop and return the object of a copy construction such as ``Particles=other``."""
        for cls in type(self).__mro__:
            value = data.get(cls.__name__)
            if isinstance(value, SubSystem):
                del data[cls.__name__]
                return value
        return None

    @classmethod
    def _from_parts(cls, fields: dict[str, np.ndarray], meta: dict[str, Any]) -> SubSystem:
        """A new instance from already frozen arrays, without calling a subclass __init__."""
        new = object.__new__(cls)
        object.__setattr__(new, "_fields", fields)
        object.__setattr__(new, "_meta", dict(meta))
        return new

    def _derive(self, fields: dict[str, np.ndarray]) -> SubSystem:
        frozen = {}
        for key, value in fields.items():
            value.setflags(write=False)
            frozen[key] = value
        return type(self)._from_parts(frozen, self._meta)

    # -- mapping-like access -----------------------------------------------------------

    @property
    def data(self) -> Mapping[str, Any]:
        """Read-only view of every attribute: arrays and metadata."""
        return MappingProxyType({**self._meta, **self._fields})

    @property
    def meta(self) -> Mapping[str, Any]:
        """Read-only view of the scalar metadata."""
        return MappingProxyType(self._meta)

    def keys(self) -> list[str]:
        """Names of the per-element arrays."""
        return list(self._fields)

    def __contains__(self, key: object) -> bool:
        return key in self._fields

    def __len__(self) -> int:
        return len(next(iter(self._fields.values()))) if self._fields else 0

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        fields = self.__dict__.get("_fields", {})
        if name in fields:
            return fields[name]
        meta = self.__dict__.get("_meta", {})
        if name in meta:
            return meta[name]
        known = [*fields, *meta]
        raise AttributeError(
            f"{type(self).__name__} has no attribute {name!r}.{did_you_mean(name, known)} "
            f"Attributes: {', '.join(known) or 'none'}."
        )

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self.__dict__.get("_fields", {}) or name in self.__dict__.get("_meta", {}):
            raise AttributeError(
                f"{type(self).__name__}.{name} is read-only; use translate(), scale() or build "
                f"a new object, e.g. {type(self).__name__}({type(self).__name__}=obj, {name}=...)"
            )
        object.__setattr__(self, name, value)

    def __dir__(self) -> list[str]:
        return sorted({*super().__dir__(), *self._fields, *self._meta})

    def __repr__(self) -> str:
        return f"{type(self).__name__}(N={len(self)}, keys={self.keys()})"

    # -- selection, iteration, concatenation ---------------------------------------------

    def __getitem__(self, selection: Selection | str) -> Any:
        if isinstance(selection, str):
            return getattr(self, selection)
        index = self._normalise(selection)
        return self._derive({key: value[index] for key, value in self._fields.items()})

    def _normalise(self, selection: Selection) -> slice | np.ndarray:
        n = len(self)
        if isinstance(selection, slice):
            return selection
        if isinstance(selection, (int, np.integer)) and not isinstance(selection, bool):
            if not -n <= selection < n:
                raise IndexError(f"Index {selection} is out of range for {n} elements")
            start = int(selection) % n
            return slice(start, start + 1)
        index = np.asarray(selection)
        if index.dtype == bool:
            if index.shape != (n,):
                raise IndexError(f"Boolean mask of shape {index.shape} does not match {n} elements")
            return index
        if index.size == 0:
            return index.astype(np.intp)
        if not np.issubdtype(index.dtype, np.integer):
            raise IndexError(f"Cannot select with an array of {index.dtype}; use ints or booleans")
        if index.min() < -n or index.max() >= n:
            raise IndexError(f"Indices {index.min()}..{index.max()} out of range for {n} elements")
        return index

    def __iter__(self) -> Iterator[SubSystem]:
        for i in range(len(self)):
            yield self[i]

    def __add__(self, other: SubSystem) -> SubSystem:
        """Concatenation over the attributes both have (the left's metadata is kept)."""
        if not isinstance(other, SubSystem):
            return NotImplemented
        common = [key for key in self._fields if key in other._fields]
        return self._derive({k: np.concatenate((self._fields[k], other._fields[k])) for k in common})

    def __iadd__(self, other: SubSystem) -> SubSystem:
        """Append ``other``; it must have every attribute this object has (extra ones are dropped)."""
        if not isinstance(other, SubSystem):
            return NotImplemented
        missing = [key for key in self._fields if key not in other._fields]
        if missing:
            raise ValueError(f"Cannot append: the other {type(other).__name__} lacks {missing}")
        self._replace({k: np.concatenate((v, other._fields[k])) for k, v in self._fields.items()})
        return self

    def copy(self) -> SubSystem:
        """An independent copy (arrays and metadata)."""
        return type(self)._from_parts({k: _frozen(v) for k, v in self._fields.items()}, dict(self._meta))

    # -- explicit in-place transforms -----------------------------------------------------

    def _replace(self, fields: dict[str, np.ndarray]) -> None:
        for value in fields.values():
            value.setflags(write=False)
        self._fields.update(fields)

    def _targets(self, attr: Sequence[str] | str | None) -> list[str]:
        names = list(self.coordinate_keys if attr is None else [attr] if isinstance(attr, str) else attr)
        unknown = [name for name in names if name not in self._fields]
        if unknown:
            raise KeyError(f"{type(self).__name__} has no attributes {unknown}; it has {self.keys()}")
        return names

    def translate(
        self, offset: float | Sequence[float], attr: Sequence[str] | str | None = None
    ) -> SubSystem:
        """Add ``offset`` (one value, or one per attribute) to ``attr`` in place; returns self."""
        names = self._targets(attr)
        offsets = np.broadcast_to(np.asarray(offset, dtype=float), (len(names),) + np.shape(offset)[1:])
        self._replace({n: self._fields[n] + o for n, o in zip(names, offsets)})
        return self

    def scale(self, factor: float, attr: Sequence[str] | str | None = None) -> SubSystem:
        """Multiply ``attr`` by ``factor`` in place; returns self."""
        self._replace({n: self._fields[n] * factor for n in self._targets(attr)})
        return self

    def noise(
        self, sigma: float, attr: Sequence[str] | str | None = None, *, seed: int | np.random.Generator
    ) -> SubSystem:
        """Add Gaussian noise of standard deviation ``sigma`` to ``attr`` in place; returns self."""
        rng = np.random.default_rng(seed)
        self._replace(
            {n: self._fields[n] + rng.normal(0.0, sigma, self._fields[n].shape) for n in self._targets(attr)}
        )
        return self
