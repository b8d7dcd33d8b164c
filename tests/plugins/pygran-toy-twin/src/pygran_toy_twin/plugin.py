"""Registers a plugin under the entry-point name "toy" that pygran-toy already uses."""
