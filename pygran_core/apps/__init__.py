"""Applications built on PyGran's public API, as a user's script would be: the hopper discharge
study of ``pygran demo`` (:mod:`~pygran_core.apps.demo`). The library never imports them."""
