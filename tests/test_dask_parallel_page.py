"""The parallel page of the guide (docs/parallel.md) runs as written: each of its Python blocks
is a script, run from a folder laid out as the repository (the example data under docs/), and
prints what the page shows in the text block after it."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pygran_core import registry
from pygran_core.testing.solvers import in_ci, require_solver

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "parallel.md"
BLOCK = re.compile(r"```python\n(.*?)```\n(?:\n```text\n(.*?)```)?", re.S)
BLOCKS = BLOCK.findall(PAGE.read_text())


def test_the_page_has_its_examples() -> None:
    assert len(BLOCKS) == 3
    assert all(shown for _, shown in BLOCKS)  # every block shows what it prints


@pytest.mark.parametrize("number", range(len(BLOCKS)))
def test_block_runs_as_written(number: int, tmp_path: Path) -> None:
    code, shown = BLOCKS[number]
    if 'engine="liggghts"' in code:
        engines = registry.available("engine")
        if "liggghts" not in engines:
            if in_ci():
                pytest.fail("CI=true and the liggghts engine is not installed")
            pytest.skip("the liggghts engine is not installed: pip install ./plugins/pygran-liggghts")
        require_solver(engines["liggghts"].spec.locate_solver)
    if ("study import" in code or ".map(" in code) and importlib.util.find_spec("distributed") is None:
        if in_ci():
            pytest.fail("CI=true and Dask is not installed: pip install pygran-core[dask]")
        pytest.skip("Dask is not installed: pip install pygran-core[dask]")
    shutil.copytree(ROOT / "docs" / "examples" / "data", tmp_path / "docs" / "examples" / "data")
    script = tmp_path / "example.py"
    script.write_text(code)
    done = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    assert done.returncode == 0, f"stdout:\n{done.stdout}\nstderr:\n{done.stderr}"
    assert done.stdout.splitlines() == shown.splitlines()
