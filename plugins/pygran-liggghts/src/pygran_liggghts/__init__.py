"""pygran-liggghts: run PyGran simulations on the LIGGGHTS DEM library."""
