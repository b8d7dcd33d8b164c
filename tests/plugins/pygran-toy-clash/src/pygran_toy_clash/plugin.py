"""Provides a second engine called "toy", to test the duplicate-name error."""

from pygran_core import hookimpl
from pygran_core.hookspecs import EngineSpec


@hookimpl
def pygran_engines():
    yield EngineSpec(name="toy", factory=object)
