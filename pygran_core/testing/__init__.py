"""Test helpers for PyGran and its plugins (need pytest): the format and engine conformance suites."""

from pygran_core.testing.engines import EngineConformance
from pygran_core.testing.formats import FormatConformance, assert_frames_equal, particle_frames

__all__ = ["EngineConformance", "FormatConformance", "assert_frames_equal", "particle_frames"]
