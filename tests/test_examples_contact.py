"""The contact-model examples (manual Listings 3.2-3.4) run as scripts and compute sensible curves."""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from matplotlib.image import imread

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
SCRIPTS = ["contact_force_displacement", "contact_restitution_yield", "contact_cohesive"]


def load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run(name: str, cwd: Path, *args: str) -> None:
    path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    env = dict(os.environ, PYTHONPATH=path, MPLBACKEND="Agg")
    subprocess.run(
        [sys.executable, str(EXAMPLES / f"{name}.py"), *args],
        cwd=cwd,
        env=env,
        check=True,
        capture_output=True,
        timeout=120,
    )


def assert_real_figure(path: Path) -> None:
    assert path.stat().st_size > 10_000
    image = imread(path)
    assert image.shape[0] > 200 and image.shape[1] > 200
    assert image[..., :3].std() > 0.05  # not a blank canvas
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 50


@pytest.mark.parametrize("name", SCRIPTS)
def test_example_writes_its_figure_in_the_working_directory(name, tmp_path):
    run(name, tmp_path)
    assert_real_figure(tmp_path / f"{name}.png")


def test_example_takes_an_output_directory(tmp_path):
    out = tmp_path / "figures"
    out.mkdir()
    run("contact_force_displacement", tmp_path, str(out))
    assert_real_figure(out / "contact_force_displacement.png")
    assert not (tmp_path / "contact_force_displacement.png").exists()


def test_force_displacement_curves():
    curves = load("contact_force_displacement").compute()
    assert set(curves) == {"SpringDashpot", "HertzMindlin"}
    for overlap, force in curves.values():
        assert len(overlap) == len(force) > 100
        assert force.max() > 0 and overlap.max() > 0
        assert overlap[0] == 0 and overlap[-1] == pytest.approx(0, abs=1e-6 * overlap.max())
    # the hooke stiffness is chosen so that both reach about the same overlap at this velocity
    assert curves["SpringDashpot"][0].max() == pytest.approx(curves["HertzMindlin"][0].max(), rel=0.05)


def test_restitution_rises_to_one_with_the_yield_pressure():
    pressure, cor, analytic = load("contact_restitution_yield").compute()
    assert len(pressure) == len(cor) == 30
    assert np.all(np.diff(cor) >= -1e-9)
    assert 0.5 < cor[0] < 0.9 and cor[-1] == pytest.approx(1, abs=1e-6)
    np.testing.assert_allclose(cor, analytic, rtol=0.02)


def test_cohesive_curves_are_complete():
    impacts = load("contact_cohesive").compute()
    slow, fast = impacts[0.04], impacts[0.4]
    for impact in (slow, fast):
        time, delta, force = impact
        assert len(time) == len(force) > 100
        assert force.max() > 0 > force.min()
    assert slow.captured and slow.restitution == 0
    assert not fast.captured and 0 < fast.restitution < 1
    assert -fast.force.min() > 3 * math.pi * 0.04 * 2e-5  # plastic flattening raises the pull-off force
