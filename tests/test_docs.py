"""The user guide: it builds without a warning, and its examples run against the current code.

``docs/`` is built with ``sphinx-build -W --keep-going`` (a broken reference, a docstring that
is not valid reStructuredText or a module that no longer imports fails), and every script in
``docs/examples/`` runs in a temporary directory, with checks on what it prints. The example
plugin package is installed with pip into a temporary target, as a user would install it.
Sphinx and myst-parser missing: a failure under CI=true, a skip elsewhere.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pygran_core import registry
from pygran_core.testing.solvers import in_ci, require_solver

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
EXAMPLES = DOCS / "examples"
#: Every script of docs/examples and the test that runs it; a new example needs a test here.
TESTED_SCRIPTS = {
    "first_simulation.py",
    "analyse_liggghts.py",
    "use_example_plugin.py",
    "nsim_liggghts.py",
    "coarse_grain_hopper.py",  # these two run in tests/test_coarse_grain.py
    "coarse_grain_bed.py",
}


def _require(*modules: str) -> None:
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        message = f"{', '.join(missing)} not installed: pip install sphinx myst-parser"
        if in_ci():
            pytest.fail(f"CI=true and the documentation tools are missing: {message}", pytrace=False)
        pytest.skip(message)


def _run(args: list[str], cwd: Path, timeout: float = 120, **env: str) -> str:
    """Run ``args`` in ``cwd``; return stdout, or fail with both streams."""
    environment = {**os.environ, "OMP_NUM_THREADS": "1", **env}  # 1 thread: steady on a busy CI machine
    done = subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=environment)
    if done.returncode != 0:
        streams = f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
        pytest.fail(f"{' '.join(args)} exited {done.returncode}\n{streams}")
    return done.stdout


def test_every_example_is_tested() -> None:
    assert {p.name for p in EXAMPLES.glob("*.py")} == TESTED_SCRIPTS


def test_docs_build_without_warnings(tmp_path: Path) -> None:
    _require("sphinx", "myst_parser")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-q",
            "-b",
            "html",
            "-d",
            str(tmp_path / "doctrees"),
            str(DOCS),
            str(tmp_path / "html"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, f"sphinx-build failed:\n{out.stdout}\n{out.stderr}"
    pages = {p.stem for p in (tmp_path / "html").glob("*.html")}
    guide = {"index", "installation", "first-simulation", "analysis", "parallel", "plugins", "command-line"}
    assert guide <= pages
    api = (tmp_path / "html" / "api" / "simulation.html").read_text()
    assert 'id="pygran_core.simulation.dem.DEM.insert"' in api  # autodoc really ran


def test_first_simulation(tmp_path: Path) -> None:
    printed = _run([sys.executable, str(EXAMPLES / "first_simulation.py")], tmp_path)
    assert "100 particles at t = 0.151 s" in printed
    assert "11 frames; mean coordination number" in printed
    assert {p.name for p in (tmp_path / "out").iterdir()} >= {"traj.h5", "energy.txt", "pygran.log"}
    coordination = float(printed.rsplit("mean coordination number", 1)[1])
    assert 3 < coordination < 6  # a settled bed, not beads in the air


def test_analyse_liggghts(tmp_path: Path) -> None:
    printed = _run([sys.executable, str(EXAMPLES / "analyse_liggghts.py")], tmp_path)
    assert "frame 2: step 30000, 423 particles, 320 wall cells" in printed
    assert "160 particles below z = 1 mm" in printed
    assert "around step 22500: 20.2 particles per 1000 steps" in printed
    assert "wrote 160 particles to low.h5" in printed
    dumps = str(EXAMPLES / "data" / "liggghts-hopper" / "particles*.dump")
    info = _run([sys.executable, "-m", "pygran_core.cli", "info", dumps], tmp_path)
    assert "timesteps:  20000 to 30000" in info


def test_example_plugin(tmp_path: Path) -> None:
    site, source = tmp_path / "site", tmp_path / "pygran-example"
    shutil.copytree(EXAMPLES / "pygran-example", source)  # the build leaves nothing in docs/
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(site),
            str(source),
        ],
        tmp_path,
    )
    env = {
        "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
        "PYGRAN_STRICT_PLUGINS": "1",
    }
    printed = _run([sys.executable, str(EXAMPLES / "use_example_plugin.py")], tmp_path, **env)
    assert "'ballistic'" in printed and "'StiffSpringDashpot'" in printed and "'xyz'" in printed
    assert "restitution 0.900" in printed
    assert "2 frames; last frame z = [1. 1.]" in printed
    plugins = _run([sys.executable, "-m", "pygran_core.cli", "plugins"], tmp_path, **env)
    assert all(name in plugins for name in ("example-engine", "example-model", "example-reader"))


def test_nsim_liggghts(tmp_path: Path) -> None:
    engines = registry.available("engine")
    if "liggghts" not in engines or "mpi" not in engines["liggghts"].spec.capabilities:
        if in_ci():
            pytest.fail("CI=true and the liggghts engine (with capability 'mpi') is not installed")
        pytest.skip("the liggghts engine is not installed: pip install ./plugins/pygran-liggghts")
    require_solver(engines["liggghts"].spec.locate_solver)
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        if in_ci():
            pytest.fail("CI=true and mpirun is missing: apt-get install -y openmpi-bin")
        pytest.skip("mpirun is missing: apt-get install -y openmpi-bin")
    flags = ["--oversubscribe"] + (["--allow-run-as-root"] if os.geteuid() == 0 else [])
    printed = _run(
        [mpirun, *flags, "-np", "2", sys.executable, str(EXAMPLES / "nsim_liggghts.py")],
        tmp_path,
        timeout=300,
    )
    assert "run0: e = 0.3, 100 particles" in printed
    assert "run1: e = 0.9, 100 particles" in printed
    for run in ("run0", "run1"):
        assert (tmp_path / "out-nsim" / run / "traj.dump").is_file()
