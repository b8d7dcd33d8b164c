"""PyGran 1.x import lines give PyGran's own modules and classes, never second copies."""

import subprocess
import sys

import pytest

import pygran_core


def test_the_original_import_lines():
    import PyGran.simulation as sim
    import PyGran.simulation.models as models
    from PyGran.modules.params import organic
    from PyGran.simulation.models import HertzMindlin

    import PyGran
    from PyGran import analysis, params, simulation

    assert simulation is sim is pygran_core.simulation
    assert analysis is pygran_core.analysis and params is pygran_core.params
    assert models is pygran_core.simulation.models and HertzMindlin is models.HertzMindlin
    assert PyGran.simulation.DEM is pygran_core.simulation.DEM
    assert organic["youngsModulus"] == 1e7
    # the aliases leave the modules' own identity alone
    assert models.__spec__.name == "pygran_core.simulation.models"
    assert PyGran.__version__ == pygran_core.__version__


def test_a_submodule_imported_first_through_the_alias_is_the_same_module():
    script = (
        "import PyGran.analysis.equilibrium as a\n"
        "import pygran_core.analysis.equilibrium as b\n"
        "import sys\n"
        "copies = {id(m) for name, m in sys.modules.items() if name.endswith('analysis.equilibrium')}\n"
        "print(a is b, len(copies))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["True", "1"]


def test_an_unknown_name_is_a_normal_import_error():
    with pytest.raises(ModuleNotFoundError, match="PyGran.simulaton"):
        import PyGran.simulaton  # noqa: F401
