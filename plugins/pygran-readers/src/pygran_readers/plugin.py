"""Registers the pygran-readers file formats with PyGran (formats arrive with the readers issue)."""
