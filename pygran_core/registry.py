"""The plugin registry: loads every installed plugin once and answers lookups by name.

Plugins are found through the entry-point groups in :data:`ENTRY_POINT_GROUPS`; each
entry point names a module of :data:`~pygran_core.hookspecs.hookimpl` functions. The
registry is built on first use and cached; :func:`refresh` drops the cache (tests,
or after installing a plugin in a running session).

Conflicts are raised here and nowhere else: two distributions using the same plugin name,
or two plugins providing an engine, model, reader or writer of the same name, is a
:class:`~pygran_core.errors.PluginError` naming both distributions. A plugin that fails to
import gives a warning naming it, or an error when ``PYGRAN_STRICT_PLUGINS=1``.
"""

from __future__ import annotations

import functools
import importlib
import os
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points, version
from pathlib import Path
from types import ModuleType
from typing import Any, Generic, TypeVar

import pluggy

from pygran_core import hookspecs
from pygran_core.errors import PluginError, PluginNotFound, did_you_mean
from pygran_core.hookspecs import EngineSpec, ModelSpec, ReaderSpec, WriterSpec

ENTRY_POINT_GROUPS = ("pygran.engines", "pygran.models", "pygran.readers")
CORE_DISTRIBUTION = "pygran-core"
#: Plugins shipped inside the core distribution itself: plugin name -> module.
BUILTIN_PLUGINS = {
    "core-models": "pygran_core.simulation.models.plugin",
    "core-formats": "pygran_core.formats.plugin",
}
STRICT_ENV = "PYGRAN_STRICT_PLUGINS"

#: Which first-party distribution provides a name, for the "how to install" hint.
FIRST_PARTY = {
    "native": "pygran-native",
    "liggghts": "pygran-liggghts",
    "yade": "pygran-yade",
    "vtk": "pygran-readers",
    "yade-vtk": "pygran-readers",
}

#: kind -> (hook name, record type)
KINDS: dict[str, tuple[str, type]] = {
    "engine": ("pygran_engines", EngineSpec),
    "model": ("pygran_models", ModelSpec),
    "reader": ("pygran_readers", ReaderSpec),
    "writer": ("pygran_writers", WriterSpec),
}

SpecT = TypeVar("SpecT")


class PluginLoadWarning(UserWarning):
    """A plugin could not be loaded and was left out."""


@dataclass(frozen=True)
class Provided(Generic[SpecT]):
    """A record from a plugin, with where it came from."""

    spec: SpecT
    plugin: str
    distribution: str
    version: str

    @property
    def origin(self) -> str:
        return f"{self.distribution} {self.version}"


@dataclass(frozen=True)
class _Registry:
    manager: pluggy.PluginManager
    plugins: dict[str, tuple[str, str]]  # plugin name -> (distribution, version)
    items: dict[str, dict[str, Provided[Any]]]  # kind -> name -> record


def _strict() -> bool:
    return os.environ.get(STRICT_ENV, "").strip().lower() in {"1", "true", "yes", "on"}


def _load_failed(message: str, exc: BaseException) -> None:
    if _strict():
        raise PluginError(f"{message} ({STRICT_ENV} is set, so this is an error)") from exc
    warnings.warn(message, PluginLoadWarning, stacklevel=4)


def _entry_points() -> Iterable[tuple[EntryPoint, str, str]]:
    """Every PyGran entry point with its distribution name and version, without repeats."""
    seen: set[tuple[str, str, str]] = set()
    for group in ENTRY_POINT_GROUPS:
        for ep in entry_points(group=group):
            dist = ep.dist.metadata["Name"] if ep.dist is not None else "<unknown distribution>"
            dist_version = ep.dist.version if ep.dist is not None else "?"
            key = (ep.name, ep.value, dist)
            if key not in seen:
                seen.add(key)
                yield ep, dist, dist_version


def _register_plugins(manager: pluggy.PluginManager) -> dict[str, tuple[str, str]]:
    plugins: dict[str, tuple[str, str]] = {}
    core_version = version(CORE_DISTRIBUTION)
    for name, module_name in BUILTIN_PLUGINS.items():
        manager.register(importlib.import_module(module_name), name=name)
        plugins[name] = (CORE_DISTRIBUTION, core_version)
    for ep, dist, dist_version in _entry_points():
        if ep.name in plugins:
            other = plugins[ep.name][0]
            raise PluginError(
                f"Two installed distributions register a PyGran plugin named {ep.name!r}: "
                f"{other} and {dist}. Uninstall one of them (pip uninstall {dist})."
            )
        try:
            module: ModuleType = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure of third-party code
            _load_failed(
                f"PyGran plugin {ep.name!r} from {dist} {dist_version} failed to import "
                f"({ep.value}): {type(exc).__name__}: {exc}. It is left out.",
                exc,
            )
            continue
        manager.register(module, name=ep.name)
        plugins[ep.name] = (dist, dist_version)
    return plugins


def _collect(
    manager: pluggy.PluginManager, plugins: dict[str, tuple[str, str]]
) -> dict[str, dict[str, Provided[Any]]]:
    items: dict[str, dict[str, Provided[Any]]] = {kind: {} for kind in KINDS}
    for kind, (hook_name, record_type) in KINDS.items():
        for impl in getattr(manager.hook, hook_name).get_hookimpls():
            dist, dist_version = plugins[impl.plugin_name]
            try:
                records = list(impl.function() or ())
                bad = [r for r in records if not isinstance(r, record_type)]
                if bad:
                    raise TypeError(f"{hook_name} must yield {record_type.__name__}, got {bad!r}")
            except Exception as exc:  # noqa: BLE001 - a broken third-party hook
                _load_failed(
                    f"PyGran plugin {impl.plugin_name!r} from {dist} {dist_version}: "
                    f"{hook_name}() failed: {type(exc).__name__}: {exc}. It is left out.",
                    exc,
                )
                continue
            for record in records:
                if record.name in items[kind]:
                    first = items[kind][record.name]
                    raise PluginError(
                        f"The {kind} name {record.name!r} is provided twice: by {first.origin} "
                        f"(plugin {first.plugin!r}) and by {dist} {dist_version} (plugin "
                        f"{impl.plugin_name!r}). Uninstall one of them."
                    )
                items[kind][record.name] = Provided(record, impl.plugin_name, dist, dist_version)
    return items


@functools.cache
def _registry() -> _Registry:
    manager = pluggy.PluginManager(hookspecs.PROJECT)
    manager.add_hookspecs(hookspecs)
    plugins = _register_plugins(manager)
    return _Registry(manager, plugins, _collect(manager, plugins))


def get_plugin_manager() -> pluggy.PluginManager:
    """The cached pluggy manager with every installed plugin registered."""
    return _registry().manager


def refresh() -> None:
    """Forget the loaded plugins; the next lookup discovers them again."""
    _registry.cache_clear()


def plugins() -> dict[str, tuple[str, str]]:
    """Loaded plugin names mapped to ``(distribution, version)``."""
    return dict(_registry().plugins)


def available(kind: str) -> dict[str, Provided[Any]]:
    """Every installed item of ``kind`` (``"engine"``, ``"model"``, ``"reader"``, ``"writer"``)."""
    if kind not in KINDS:
        raise ValueError(f"Unknown plugin kind {kind!r}; known: {', '.join(KINDS)}")
    return dict(_registry().items[kind])


def install_hint(name: str) -> str:
    """How to install the plugin that provides ``name``, if it is a first-party one."""
    dist = FIRST_PARTY.get(name)
    if dist is None:
        return "Install the plugin that provides it (a package with a PyGran entry point)."
    return f"Install it with: pip install {dist} (from a PyGran checkout: pip install ./plugins/{dist})."


def lookup(kind: str, name: str) -> Provided[Any]:
    """The installed item of ``kind`` called ``name``, or :class:`PluginNotFound` saying what is."""
    items = available(kind)
    if name in items:
        return items[name]
    listing = ", ".join(f"{n} ({p.origin})" for n, p in sorted(items.items())) or "none"
    raise PluginNotFound(
        f"No {kind} named {name!r} is installed.{did_you_mean(name, items)} "
        f"Installed {kind}s: {listing}. {install_hint(name)}"
    )


def get_engine(name: str) -> EngineSpec:
    return lookup("engine", name).spec


def get_model(name: str) -> ModelSpec:
    return lookup("model", name).spec


def engines_with(capability: str) -> list[str]:
    """Names of installed engines that declare ``capability``."""
    return sorted(n for n, p in available("engine").items() if capability in p.spec.capabilities)


def extension_chain(path: Path) -> list[str]:
    """Suffix chains of a file name, longest first: ``a.dump.gz`` -> ``.dump.gz``, ``.gz``."""
    suffixes = [s.lower() for s in path.suffixes]
    return ["".join(suffixes[i:]) for i in range(len(suffixes))]


def _by_extension(kind: str, path: Path) -> Any | None:
    items = available(kind)
    for chain in extension_chain(path):
        for provided in items.values():
            if chain in provided.spec.extensions:
                return provided.spec
    return None


def _format_listing(kind: str) -> str:
    items = available(kind)
    return (
        "; ".join(f"{n} ({', '.join(p.spec.extensions)})" for n, p in sorted(items.items()))
        or "none installed (pip install ./plugins/pygran-readers)"
    )


def reader_for(path: Path, format: str | None = None) -> ReaderSpec:
    """The reader for ``path``: ``format`` if given, else ``can_open``, else the extension."""
    if format is not None:
        return lookup("reader", format).spec
    for provided in available("reader").values():
        can_open: Callable[[Path], bool] | None = provided.spec.can_open
        if can_open is not None and can_open(path):
            return provided.spec
    spec = _by_extension("reader", path)
    if spec is None:
        raise PluginNotFound(
            f"No installed reader recognises {str(path)!r}. Pass format=... with one of the "
            f"readers: {_format_listing('reader')}."
        )
    return spec


def writer_for(path: Path, format: str | None = None) -> WriterSpec:
    """The writer for ``path``: ``format`` if given, else the extension."""
    if format is not None:
        return lookup("writer", format).spec
    spec = _by_extension("writer", path)
    if spec is None:
        raise PluginNotFound(
            f"No installed writer for {str(path)!r}. Use one of the extensions of the "
            f"writers: {_format_listing('writer')}, or pass format=..."
        )
    return spec
