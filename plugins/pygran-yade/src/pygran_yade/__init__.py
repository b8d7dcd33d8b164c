"""pygran-yade: run PyGran simulations on YADE."""
