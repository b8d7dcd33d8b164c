"""The :class:`SubSystem` base: a set of elements (particles, mesh cells) with named arrays.

A SubSystem maps attribute names to per-element numpy arrays of one length N (1-D, or
N x k for vectors such as mesh cells) and holds metadata (``timestep``, ``box``, ``units``,
and for meshes the shared ``points``). Arrays are read-only to the user; the methods that
change them (:meth:`translate`, :meth:`scale`, :meth:`noise`, :meth:`convert`) replace them
explicitly. Slicing with an int, a slice, a list, an integer array or a boolean mask returns
a new object of the same class.

The original PyGran's forms work beside today's: ``obj.keys`` prints and iterates as the
attribute names and ``obj.keys()`` returns them as a list; ``obj.units`` is the unit
system's name and ``obj.units("micro")`` converts (as :meth:`convert`);
``translate(value, attr)`` takes the original's argument order and keywords.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from types import MappingProxyType
from typing import Any, TypeVar

import numpy as np

from pygran_core import units as _units
from pygran_core.errors import AttributeProblem, ConfigError, SelectionError, did_you_mean
from pygran_core.io import Frame, open_writer

Selection = int | slice | Sequence[int] | np.ndarray

_XYZ = ("x", "y", "z")

#: LIGGGHTS column (and metadata) names -> physical dimension, for unit conversion.
DIMENSIONS: dict[str, str] = {
    **dict.fromkeys((*_XYZ, "xu", "yu", "zu", "radius", "diameter", "box"), "length"),
    **dict.fromkeys(("vx", "vy", "vz"), "velocity"),
    **dict.fromkeys(("fx", "fy", "fz"), "force"),
    **dict.fromkeys(("omegax", "omegay", "omegaz"), "angular_velocity"),
    **dict.fromkeys(("tqx", "tqy", "tqz"), "torque"),
    "mass": "mass",
    "density": "density",
    "time": "time",
}


_S = TypeVar("_S", bound="SubSystem")


class Keys(tuple[str, ...]):
    """Attribute names: prints and iterates as the original's ``keys`` property; calling it
    (today's ``keys()``) returns them as a list."""

    def __call__(self) -> list[str]:
        return list(self)

    def __repr__(self) -> str:
        return repr(list(self))


def _frozen(values: Any) -> np.ndarray:
    """``values`` as an array nothing can write to: itself when it is read-only down to the
    array that owns its memory (a frame :class:`~pygran_core.analysis.system.System` read, an
    attribute of another object), else a read-only copy."""
    if isinstance(values, np.ndarray) and _read_only(values):
        return values
    array = np.array(values, copy=True)
    array.setflags(write=False)
    return array


def _read_only(array: np.ndarray) -> bool:
    """Whether ``array`` and every array it views are read-only, the last one owning its memory."""
    base: Any = array
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return False
        if base.base is None:
            return True
        base = base.base
    return False


def _signed_geometric_mean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    product = np.multiply.outer(np.asarray(a, dtype=float), np.asarray(b, dtype=float)).ravel()
    return np.sign(product) * np.sqrt(np.abs(product))


class SubSystem:
    """Named per-element arrays plus metadata.

    ``SubSystem(x=[...], y=[...], timestep=100)`` builds one from arrays (anything with a
    length) and scalars; ``SubSystem(SubSystem=other)`` (or ``Particles(Particles=other)``,
    any class name of the object's hierarchy) copies another. ``units`` (default ``"si"``)
    names the unit system the numbers are in; :meth:`convert` changes it.
    """

    #: Attributes that :meth:`translate`, :meth:`scale` and :meth:`noise` act on by default.
    coordinate_keys: tuple[str, ...] = _XYZ
    #: Attribute name -> dimension (a key of :data:`pygran_core.units.DIMENSIONS`) for :meth:`convert`;
    #: attributes not listed (``id``, ``type``, custom ``c_*`` columns) are left as they are.
    dimensions: Mapping[str, str] = DIMENSIONS

    _fields: dict[str, np.ndarray]
    _meta: dict[str, Any]

    def __init__(self, **data: Any) -> None:
        source = self._copy_source(data)
        fields: dict[str, np.ndarray] = {}
        meta: dict[str, Any] = {"units": "si"}
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
            raise ConfigError(f"{type(self).__name__} attributes have different lengths: {lengths}")
        _units.exponent("length", meta["units"], "si")  # an unknown unit system is a ConfigError
        object.__setattr__(self, "_fields", fields)
        object.__setattr__(self, "_meta", meta)
        object.__setattr__(self, "_origin", None)

    def _copy_source(self, data: dict[str, Any]) -> SubSystem | None:
        """Pop and return the object of a copy construction such as ``Particles=other``."""
        for cls in type(self).__mro__:
            value = data.get(cls.__name__)
            if isinstance(value, SubSystem):
                del data[cls.__name__]
                return value
        return None

    @classmethod
    def _from_parts(cls: type[_S], fields: dict[str, np.ndarray], meta: dict[str, Any]) -> _S:
        """A new instance from already frozen arrays, without calling a subclass __init__."""
        new = object.__new__(cls)
        object.__setattr__(new, "_fields", fields)
        object.__setattr__(new, "_meta", dict(meta))
        object.__setattr__(new, "_origin", None)
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
        """Read-only view of the metadata."""
        return MappingProxyType(self._meta)

    @property
    def keys(self) -> Keys:
        """Names of the per-element arrays: ``for k in obj.keys`` or ``obj.keys()`` (a list)."""
        return Keys(self._fields)

    @property
    def units(self) -> _units.UnitName:
        """The unit system of the numbers; ``obj.units("micro")`` converts, as :meth:`convert`."""
        return _units.UnitName(self._meta["units"], self.convert)

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
        raise AttributeProblem(
            f"{type(self).__name__} has no attribute {name!r}.{did_you_mean(name, known)} "
            f"Attributes: {', '.join(known) or 'none'}."
        )

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self.__dict__.get("_fields", {}) or name in self.__dict__.get("_meta", {}):
            raise AttributeProblem(
                f"{type(self).__name__}.{name} is read-only; use translate(), scale() or build "
                f"a new object, e.g. {type(self).__name__}({type(self).__name__}=obj, {name}=...)"
            )
        object.__setattr__(self, name, value)

    def __dir__(self) -> list[str]:
        return sorted({*super().__dir__(), *self._fields, *self._meta})

    def __repr__(self) -> str:
        return f"{type(self).__name__}(N={len(self)}, keys={self.keys!r})"

    # -- selection, iteration, concatenation ---------------------------------------------

    def __getitem__(self, selection: Selection | str) -> Any:
        if isinstance(selection, str):
            return getattr(self, selection)
        index = self._normalise(selection)
        new = self._derive({key: value[index] for key, value in self._fields.items()})
        if self._origin is not None:
            units, fields, meta = self._origin
            sliced = {key: value[index] for key, value in fields.items()}
            object.__setattr__(new, "_origin", (units, sliced, meta))
        return new

    def _normalise(self, selection: Selection) -> slice | np.ndarray:
        n = len(self)
        if isinstance(selection, slice):
            return selection
        if isinstance(selection, (int, np.integer)) and not isinstance(selection, bool):
            if not -n <= selection < n:
                raise SelectionError(f"Index {selection} is out of range for {n} elements")
            start = int(selection) % n
            return slice(start, start + 1)
        index = np.asarray(selection)
        if index.dtype == bool:
            if index.shape != (n,):
                raise SelectionError(f"Boolean mask of shape {index.shape} does not match {n} elements")
            return index
        if index.size == 0:
            return index.astype(np.intp)
        if index.dtype.kind == "f" and np.isfinite(index).all() and np.array_equal(index, np.round(index)):
            index = index.astype(np.intp)  # whole numbers, e.g. a column of Neighbors.overlaps
        if not np.issubdtype(index.dtype, np.integer):
            raise SelectionError(
                f"Cannot select {type(self).__name__} elements with {selection!r:.60}: use an int, a slice, "
                "a list or array of ints, or a boolean mask"
            )
        if index.min() < -n or index.max() >= n:
            raise SelectionError(f"Indices {index.min()}..{index.max()} out of range for {n} elements")
        return index

    def __iter__(self) -> Iterator[SubSystem]:
        for i in range(len(self)):
            yield self[i]

    def __add__(self, other: SubSystem) -> SubSystem:
        """Concatenation over the attributes both have (the left's metadata is kept)."""
        if not isinstance(other, SubSystem):
            return NotImplemented
        self._check_same_units(other)
        common = [key for key in self._fields if key in other._fields]
        return self._derive({k: np.concatenate((self._fields[k], other._fields[k])) for k in common})

    def __iadd__(self, other: SubSystem) -> SubSystem:
        """Append ``other``; it must have every attribute this object has (extra ones are dropped)."""
        if not isinstance(other, SubSystem):
            return NotImplemented
        self._check_same_units(other)
        missing = [key for key in self._fields if key not in other._fields]
        if missing:
            raise ConfigError(
                f"Cannot append with +=: the other {type(other).__name__} lacks {missing}; use + to keep "
                "only the common attributes"
            )
        self._replace({k: np.concatenate((v, other._fields[k])) for k, v in self._fields.items()})
        return self

    def __mul__(self, other: SubSystem) -> SubSystem:
        """The manual's product: ``len(self) * len(other)`` elements whose attributes are the
        geometric means of every pair, ``sqrt(a_i * b_j)`` at index ``i * len(other) + j``.

        Only 1-D floating-point attributes both objects have are kept (the left's metadata
        too): integer labels such as ``id`` and ``type`` have no geometric mean and are left
        out. A product ``a_i * b_j < 0`` (e.g. coordinates on both sides of the origin) gives
        ``-sqrt(|a_i * b_j|)``, so the result stays real.
        """
        if not isinstance(other, SubSystem):
            return NotImplemented
        self._check_same_units(other)
        common = [
            k
            for k, v in self._fields.items()
            if v.ndim == 1 and v.dtype.kind == "f" and k in other._fields and other._fields[k].ndim == 1
        ]
        return self._derive({k: _signed_geometric_mean(self._fields[k], other._fields[k]) for k in common})

    def _check_same_units(self, other: SubSystem) -> None:
        if self.units != other.units:
            raise ConfigError(
                f"Cannot combine {type(self).__name__} in {self.units!r} units with one in "
                f"{other.units!r} units; convert() one of them first"
            )

    def copy(self) -> SubSystem:
        """An independent copy: its own metadata and arrays (read-only ones are shared, as
        neither object can change them)."""
        return type(self)._from_parts({k: _frozen(v) for k, v in self._fields.items()}, dict(self._meta))

    # -- explicit in-place transforms -----------------------------------------------------

    def _replace(self, arrays: dict[str, np.ndarray]) -> None:
        """Swap in new arrays (per-element fields or array metadata such as mesh points)."""
        for key, value in arrays.items():
            value.setflags(write=False)
            (self._fields if key in self._fields else self._meta)[key] = value
        object.__setattr__(self, "_origin", None)

    def _array(self, name: str) -> np.ndarray:
        return self._fields[name] if name in self._fields else self._meta[name]

    def _targets(self, attr: Sequence[str] | str | None) -> list[str]:
        names = list(self.coordinate_keys if attr is None else [attr] if isinstance(attr, str) else attr)
        arrays = [*self._fields, *(k for k, v in self._meta.items() if isinstance(v, np.ndarray))]
        unknown = [name for name in names if name not in arrays]
        if unknown:
            raise ConfigError(f"{type(self).__name__} has no attributes {unknown}; it has {arrays}")
        return names

    def translate(self, value: float | Sequence[float], attr: Sequence[str] | str | None = None) -> SubSystem:
        """Add ``value`` (one number, or one per attribute) to ``attr`` in place; returns self.

        The original's call ``translate(value=(dx, dy, dz), attr=('x', 'y', 'z'))`` works as
        is; ``attr`` defaults to the positions. For a vector attribute such as mesh
        ``points`` (N, 3), ``value`` may be a 3-vector.
        """
        names = self._targets(attr)
        offset = np.asarray(value, dtype=float)
        if len(names) == 1 and self._array(names[0]).ndim == 2:
            self._replace({names[0]: self._array(names[0]) + offset})
            return self
        if offset.ndim > 1 or offset.size not in (1, len(names)):
            raise ConfigError(
                f"translate: give one value or one per attribute ({len(names)} for {names}), got {value!r}"
            )
        offsets = np.broadcast_to(offset, (len(names),))
        self._replace({n: self._array(n) + o for n, o in zip(names, offsets)})
        return self

    def scale(self, value: float, attr: Sequence[str] | str | None = None) -> SubSystem:
        """Multiply ``attr`` (default the positions) by ``value`` in place; returns self."""
        self._replace({n: self._array(n) * value for n in self._targets(attr)})
        return self

    def noise(
        self,
        sigma: float,
        attr: Sequence[str] | str | None = None,
        *,
        seed: int | np.random.Generator | None = None,
    ) -> SubSystem:
        """Add Gaussian noise of standard deviation ``sigma`` to ``attr`` in place; returns self.

        ``seed`` makes it reproducible; without it the noise differs on every call (as the original's).
        """
        if sigma < 0:
            raise ConfigError(f"noise: sigma must be >= 0, got {sigma}")
        rng = np.random.default_rng(seed)
        self._replace(
            {n: self._array(n) + rng.normal(0.0, sigma, self._array(n).shape) for n in self._targets(attr)}
        )
        return self

    # -- units and output -------------------------------------------------------------------

    def convert(self, units: str) -> SubSystem:
        """Express every attribute of known dimension in ``units`` (si, cgs, micro, nano), in place.

        Each conversion is computed from the numbers as they were before the first
        conversion, so converting back returns exactly the original arrays
        (``p.convert("micro").convert("si")`` is bit-identical). Returns self.
        """
        _units.exponent("length", units, "si")  # validates the name
        if self._origin is None:
            object.__setattr__(self, "_origin", (self.units, dict(self._fields), dict(self._meta)))
        source, fields, meta = self._origin

        def to_target(key: str, value: Any) -> Any:
            dimension = self.dimensions.get(key)
            if dimension is None or value is None or units == source:
                return value
            return _units.convert(np.asarray(value, dtype=float), dimension, source, units)

        new_fields = {k: to_target(k, v) for k, v in fields.items()}
        for value in new_fields.values():
            value.setflags(write=False)
        self._fields.clear()
        self._fields.update(new_fields)
        self._meta.clear()
        self._meta.update({k: to_target(k, v) for k, v in meta.items()}, units=units)
        return self

    @classmethod
    def _frame_kwargs(cls, frame: Frame) -> dict[str, Any]:
        """Constructor keywords for one :class:`~pygran_core.io.Frame` (its arrays and metadata)."""
        meta = {"timestep": frame.timestep, "time": frame.time, "box": frame.box, "boundary": frame.boundary}
        return {
            **frame.arrays,
            **{k: v for k, v in meta.items() if v is not None},
            "units": frame.attrs.get("units", "si"),
        }

    def _to_frame(self) -> Frame:
        box = self._meta.get("box")
        boundary = self._meta.get("boundary") or (None if box is None else ("ff", "ff", "ff"))
        return Frame(
            arrays=dict(self._fields),
            timestep=self._meta.get("timestep"),
            time=self._meta.get("time"),
            box=None if box is None else np.asarray(box, dtype=float),
            boundary=boundary,
            attrs={"units": self.units},
        )

    def write(self, path: str | os.PathLike[str], format: str | None = None, **options: Any) -> None:
        """Write this object as one frame to ``path`` (any registered writer; by extension or ``format``)."""
        with open_writer(path, format, **options) as writer:
            writer.write_frame(self._to_frame())
