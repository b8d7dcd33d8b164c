"""PyGran's exceptions and warnings: every error PyGran raises on purpose derives from
:class:`PyGranError`, every warning it issues from :class:`PyGranWarning`."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class PyGranError(Exception):
    """Base class of every error raised by PyGran and its plugins."""


class ConfigError(PyGranError, ValueError):
    """A parameter, keyword or material value is invalid."""


class PluginNotFound(PyGranError, LookupError):
    """No installed plugin provides the requested engine, model, reader or writer."""


class PluginError(PyGranError):
    """A plugin failed to load, or two plugins claim the same name."""


class UnsupportedFeature(PyGranError):
    """The chosen engine (or format) cannot honour a request."""


class ReadError(PyGranError):
    """A file cannot be read; the message names the file, and where known the frame and line."""


class WriteError(PyGranError, OSError):
    """A file could not be written: no space left, or another writer holds it; the message
    names the file, and every frame written before stays readable."""


class EngineError(PyGranError):
    """The solver behind an engine reported an error or died."""


class SelectionError(PyGranError, IndexError):
    """A selection (index, slice, list, mask) or frame that does not fit the analysed object."""


class AttributeProblem(PyGranError, AttributeError):
    """An attribute of an analysed object that does not exist, or one that is read-only."""


class PyGranWarning(UserWarning):
    """Base class of PyGran's warnings: something ran, but probably not as the user meant."""


class TimeStepWarning(PyGranWarning):
    """The time step resolves contacts poorly (see :mod:`pygran_core.simulation.timestep`)."""


class LostParticlesWarning(PyGranWarning):
    """Particles left the domain, became non-finite or were deleted during a run."""


class InsertionWarning(PyGranWarning):
    """An insertion placed fewer particles than it was asked for: its region is full."""


class ServoWarning(PyGranWarning):
    """A servo wall's controller does not settle: the force on it swings about its target
    from step to step (the gain is too high for the bed it presses)."""


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """Return ``" Did you mean 'x'?"`` for the closest choice, or an empty string."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" Did you mean {close[0]!r}?" if close else ""


def unknown_key(kind: str, key: str, known: Iterable[str]) -> ConfigError:
    """A :class:`ConfigError` for an unknown keyword that suggests the closest known one."""
    known = sorted(known)
    return ConfigError(f"Unknown {kind} {key!r}.{did_you_mean(key, known)} Known: {', '.join(known)}.")
