"""Test helpers for PyGran and its plugins, each in its module: the engine and format conformance
suites (:mod:`~pygran_core.testing.engines`, :mod:`~pygran_core.testing.formats`; they need
pytest), the physics checks of ``pygran validate`` (:mod:`~pygran_core.testing.validation`) and
:func:`~pygran_core.testing.solvers.require_solver` for tests that need a solver."""
