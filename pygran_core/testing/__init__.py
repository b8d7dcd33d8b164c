"""Test helpers for PyGran and its plugins (need pytest): the format conformance suite."""

from pygran_core.testing.formats import FormatConformance, assert_frames_equal, particle_frames

__all__ = ["FormatConformance", "assert_frames_equal", "particle_frames"]
