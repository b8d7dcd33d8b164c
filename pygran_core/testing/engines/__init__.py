"""Conformance tests every DEM engine passes, in the style of MDAnalysis' reader tests.

An engine plugin's tests subclass :class:`EngineConformance` once::

    class TestNative(EngineConformance):
        engine = "native"
        options = {"threads": 1}

The suite runs every front-end call of :class:`~pygran_core.simulation.DEM` (``insert`` by
pack and by rate with schedules, every ``createParticles`` form, ``setupWall`` primitive and
mesh, every ``moveMesh`` style, ``addViscous``, ``monitor``, ``set``, ``run``, ``remove``,
``extract*``, ``close``, a restart round trip), settles a sphere and a stack of two on a
floor for every material of :data:`pygran_core.params.MATERIALS`, and compares impacts of
every contact model with the reference models (:mod:`pygran_core.testing.validation`). Each optional
setting is run with and without: it must change the result (as its closed form says, where
one exists) or raise :class:`~pygran_core.errors.UnsupportedFeature`, never be ignored.

What runs is decided by the engine's declared capabilities (``EngineSpec.capabilities``):
a declared capability is checked in full, an undeclared one must raise
:class:`UnsupportedFeature`. Features of the suite that no capability names
(:data:`SUITE_FEATURES`: ``createParticles`` forms, ``insert``, ``set``, drag, optional
monitor quantities...) are required unless the subclass lists them in
:attr:`EngineConformance.refuses`, and then they must raise :class:`UnsupportedFeature`.

The mesh tests read ``meshes/silo.stl`` from the ``data_dir`` fixture (the repository's
``tests/data``, from the root ``conftest.py``); a subclass may override the fixture. A
subclass whose engine needs installing first overrides the class-scoped ``engine_plugin``
fixture. A missing engine or solver fails under ``CI=true`` and skips elsewhere.
Scenarios use small particle counts and few steps; the set-ups several tests share run once
per class. Requires pytest.

The checks are grouped by area, one mixin of :class:`~pygran_core.testing.engines.base.EngineSuite`
(the set-up they share) per module: ``creation`` (``createParticles``, extracts, ``close``),
``insertion``, ``walls`` (primitive, mesh, ``moveMesh``), ``forces`` (drag, gravity, monitors,
``set``), ``runs`` (time-step check, lost particles, trajectory, options), ``restart``,
``physics`` (pair tables, impacts, settles, cohesion, rolling) and ``user_errors``.
"""

from pygran_core.testing.engines.base import GRAVITY, MATERIAL, MODELS, RADIUS, SUITE_FEATURES, G
from pygran_core.testing.engines.creation import CreationChecks
from pygran_core.testing.engines.forces import ForceChecks
from pygran_core.testing.engines.insertion import InsertionChecks
from pygran_core.testing.engines.physics import PhysicsChecks
from pygran_core.testing.engines.restart import RestartChecks
from pygran_core.testing.engines.runs import RunChecks
from pygran_core.testing.engines.user_errors import MistakeChecks
from pygran_core.testing.engines.walls import WallChecks

__all__ = ["G", "GRAVITY", "MATERIAL", "MODELS", "RADIUS", "SUITE_FEATURES", "EngineConformance"]


class EngineConformance(
    CreationChecks,
    InsertionChecks,
    WallChecks,
    ForceChecks,
    RunChecks,
    RestartChecks,
    PhysicsChecks,
    MistakeChecks,
):
    """Base class of an engine's conformance tests: every area's checks; see the module docstring."""
