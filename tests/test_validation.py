"""``pygran validate``'s checks: all pass on the native engine, and each one can fail."""

import math
import re

import pytest

from pygran_core.errors import ConfigError, PluginNotFound
from pygran_core.simulation.models import HertzMindlin, SpringDashpot, ThorntonNing
from pygran_core.testing import validation
from pygran_core.testing.validation import SOFT, CheckResult


def test_every_check_passes_on_native(tmp_path):
    started = []
    results = validation.run_validation("native", output=tmp_path, progress=started.append)
    assert started == list(validation.CHECKS)
    table = validation.format_table(results)
    assert all(r.passed for r in results), table
    assert validation.exit_status(results) == 0
    assert [r.name for r in results] == [
        "Hertz contact time",
        "Hertz max overlap",
        "restitution SpringDashpot",
        "restitution HertzMindlin",
        "restitution ThorntonNing",
        *(f"Thornton-Ning e at V_y/V = {ratio:g}" for ratio in (1, 0.5, 0.2, 0.1, 0.05, 0.01)),
        "JKR pull-off force",
        "rolling speed / v0 (mu=0.2)",
        "rolling speed / v0 (mu=0.8)",
        "energy change",
        "packing fraction (settle)",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(validation.CHECKS)
    lines = table.splitlines()
    assert lines[0].split() == ["check", "expected", "obtained", "tolerance", "result", "notes"]
    assert len(lines) == 1 + len(results) and all(" pass" in line for line in lines[1:])


def test_hertz_check_fails_for_a_damped_impact(tmp_path):
    damped = dict(SOFT, coefficientRestitution=0.7)
    results = validation.check_hertz("native", tmp_path, material=damped)
    assert [r.passed for r in results] == [False, False]
    time, overlap = results
    assert time.obtained > 1.02 * time.expected and overlap.obtained < 0.95 * overlap.expected


def test_rolling_check_fails_without_friction(tmp_path):
    (result,) = validation.check_rolling("native", tmp_path, frictions=(0.0,))
    assert result.passed is False
    assert result.obtained == pytest.approx(1.0, rel=1e-6)  # slides forever at its initial speed


def test_energy_check_fails_with_dissipation(tmp_path):
    lossy = dict(SOFT, coefficientRestitution=0.95, coefficientFriction=0.0)
    (result,) = validation.check_energy("native", tmp_path, material=lossy)
    assert result.passed is False and result.obtained > 0.01


def test_packing_check_fails_for_frictionless_spheres(tmp_path):
    (result,) = validation.check_packing("native", tmp_path, material=dict(SOFT, coefficientFriction=0.0))
    assert result.passed is False and result.obtained > 0.62


def test_restitution_check_fails_when_the_simulation_cannot_run(tmp_path):
    incomplete = {SpringDashpot: dict(SOFT, coefficientRestitution=0.5)}  # no characteristicVelocity
    (result,) = validation.check_restitution("native", tmp_path, materials=incomplete)
    assert result.passed is False and result.obtained is None
    assert result.notes.startswith("error: ConfigError") and "characteristicVelocity" in result.notes
    assert validation.exit_status([result]) == 1
    assert " FAIL " in validation.format_table([result])


@pytest.mark.parametrize("yield_pressure", [3e4, 1e5, 2e5])
def test_thornton_closed_form_matches_the_reference_model(yield_pressure):
    material = dict(validation.IMPACT_MATERIALS[ThorntonNing], yieldPress=yield_pressure)
    reference = ThorntonNing(material=dict(material, radius=1e-3)).restitution(0.1)
    assert validation.thornton_restitution(material, 1e-3, 0.1) == pytest.approx(reference, rel=1e-6)
    assert reference < 0.99  # the impact yields


def test_hertz_closed_forms_match_the_reference_model():
    material = dict(SOFT, coefficientRestitution=1.0)
    impact = HertzMindlin(material=dict(material, radius=1e-3)).displacement(0.1)
    args = (validation.sphere_mass(material, 1e-3), 1e-3, validation.contact_modulus(material), 0.1)
    assert validation.hertz_contact_time(*args) == pytest.approx(impact.contact_time, rel=1e-6)
    assert validation.hertz_max_overlap(*args) == pytest.approx(impact.max_overlap, rel=1e-6)
    assert validation.hertz_contact_time(*args) == pytest.approx(
        2.868 * (args[0] ** 2 / (args[1] * args[2] ** 2 * 0.1)) ** 0.2, rel=1e-4
    )


def test_an_engine_without_the_models_reports_unsupported_and_fails_when_nothing_ran(with_plugins, tmp_path):
    with_plugins("pygran-toy")  # point masses: spring-dashpot only, no walls
    results = validation.run_validation("toy", checks=["restitution", "packing"], output=tmp_path)
    assert [r.passed for r in results] == [None] * 4
    assert all(r.unsupported and r.obtained is None for r in results)
    assert results[0].notes.startswith("The toy engine does not support plane walls")
    assert "does not support the HertzMindlin contact model" in results[1].notes
    assert validation.format_table(results).count(" unsupported ") == 4
    assert validation.exit_status(results) == 1  # nothing was validated
    assert validation.summary(results, "toy") == (
        "no check could run on the toy engine: all 4 rows need a feature it lacks (see the notes), "
        "so nothing was validated"
    )


def test_validate_command_fails_when_no_check_could_run(with_plugins, capsys):
    from pygran_core.cli import main

    with_plugins("pygran-toy")
    assert main(["validate", "--engine", "toy", "--check", "restitution"]) == 1
    out, err = capsys.readouterr()
    assert out.count(" unsupported ") == 3
    assert "pygran: error: no check could run on the toy engine: all 3 rows" in err


def test_pass_fail_and_unsupported_rows():
    rows = [
        CheckResult("relative", 2.0, 2.03, 0.02),
        CheckResult("absolute", 0.585, 0.63, 0.035, relative=False),
        CheckResult("not finite", 1.0, math.inf, 0.5),
        CheckResult("skipped by the engine", 1.0, None, 0.01, unsupported=True),
    ]
    assert [r.passed for r in rows] == [True, False, False, None]
    assert [r.status for r in rows] == ["pass", "FAIL", "FAIL", "unsupported"]
    assert validation.exit_status(rows) == 1 and validation.exit_status(rows[::3]) == 0
    assert validation.exit_status(rows[3:]) == 1 and validation.exit_status([]) == 1
    assert validation.summary(rows, "x") == "1 passed, 2 failed, 1 unsupported on the x engine"


def test_table_keeps_rows_on_one_line_and_long_notes_below():
    crashed = CheckResult("crash", 1.0, None, 0.01, notes="error: EngineError: died. Log:\nline 1\nline 2")
    table = validation.format_table([CheckResult("fine", 0.5, 0.5, 0.01, units="s"), crashed])
    lines = table.splitlines()
    assert lines[1].split() == ["fine", "0.5", "s", "0.5", "s", "±1", "%", "pass"]
    assert lines[2].split() == [
        "crash",
        "1",
        "-",
        "±1",
        "%",
        "FAIL",
        "error:",
        "EngineError:",
        "died.",
        "Log:",
    ]
    assert lines[3:] == ["", "crash: error: EngineError: died. Log:", "line 1", "line 2"]


def test_unknown_check_and_engine_are_clear_errors():
    with pytest.raises(ConfigError, match=re.escape("Unknown check 'energie'. Did you mean 'energy'?")):
        validation.run_validation("native", checks=["energie"])
    with pytest.raises(PluginNotFound, match="No engine named 'nativ'"):
        validation.run_validation("nativ")
