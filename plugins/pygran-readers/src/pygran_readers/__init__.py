"""pygran-readers: trajectory and mesh file formats for PyGran."""
