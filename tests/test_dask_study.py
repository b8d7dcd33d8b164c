"""Parameter studies (pygran_core.simulation.study) of tiny native runs on a Dask LocalCluster of two
worker processes: a sphere hits a floor and each run measures its restitution, one run fails on
purpose (an invalid restitution: retried, reported, the others kept), and a study killed midway
is resumed from its journal without running its finished runs again.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import ConfigError, PyGranWarning, UnsupportedFeature
from pygran_core.simulation.study import Study, current, grid, rows_of
from pygran_core.testing.solvers import in_ci, require_solver

try:
    import cloudpickle
    import distributed
except ImportError:  # pragma: no cover - depends on the installation
    if in_ci():
        raise
    pytest.skip("Dask is not installed: pip install pygran-core[dask]", allow_module_level=True)
cloudpickle.register_pickle_by_value(sys.modules[__name__])  # run processes cannot import a test module

ROWS = [{"restitution": 0.3}, {"restitution": 0.6}, {"restitution": 1.5}, {"restitution": 0.9}]
SPEED = 0.1
#: The same impact as a study's script: it reads its run, waits for a gate file in the study's
#: folder when asked (a long run), and reports the restitution it measured.
SCRIPT = """
import os
import time

from pygran_core import params, registry, simulation
from pygran_core.simulation import study

run = study.current()
(run.output / "pid").write_text(str(os.getpid()))
while run.parameters["slow"] and not (run.output.parent / "gate").exists():
    time.sleep(0.05)
glass = dict(params.glass, coefficientRestitution=run.parameters["restitution"])
dt = simulation.models.HertzMindlin(material=dict(glass, radius=1e-3)).contactTime(0.1) / 200
with simulation.DEM(
    engine="native", box=(-2e-3, 2e-3, -2e-3, 2e-3, -1e-3, 4e-3), boundary=("f", "f", "f"),
    gravity=(0, 0, 0, -1), dt=dt, output=run.output, species=({"material": glass, "radius": 1e-3},),
) as sim:
    sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
    sim.createParticles(1, "single", 0.0, 0.0, 1e-3 + 0.05 * dt, vel=(0, 0, -0.1))
    sim.run(600)
    run.report(e=float(sim.extractVelocities()[0, 2] / 0.1))
"""


def impact(output: Path, restitution: float) -> dict[str, Any]:
    """One run as a user writes it: a glass sphere hits a floor at 0.1 m/s; its restitution."""
    glass = dict(params.glass, coefficientRestitution=restitution)
    radius = 1e-3
    dt = simulation.models.HertzMindlin(material=dict(glass, radius=radius)).contactTime(SPEED) / 200
    with simulation.DEM(
        engine="native",
        box=(-2e-3, 2e-3, -2e-3, 2e-3, -1e-3, 4e-3),
        boundary=("f", "f", "f"),
        gravity=(0, 0, 0, -1),
        dt=dt,
        output=output,
        species=({"material": glass, "radius": radius},),
    ) as sim:
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, radius + 0.5 * SPEED * dt, vel=(0, 0, -SPEED))
        sim.run(600)
        return {"e": sim.extractVelocities()[0, 2] / SPEED, "pid": os.getpid()}


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as dask_client,
    ):
        yield dask_client


def test_four_runs_one_failing(tmp_path: Path, client: Any, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.warns(PyGranWarning, match=r"1 of 4 runs failed after 2 attempts: run 2 \(ConfigError"):
        study = Study(impact, parameters=ROWS, output=tmp_path / "study", client=client, progress=True)
        table = study.run()
    progress = capsys.readouterr().err.replace("\r", "\n").splitlines()[-1]
    assert progress.startswith("study: 100%") and "4/4" in progress and "failed 1" in progress
    assert [row["run"] for row in table] == [0, 1, 2, 3]
    assert [row["status"] for row in table] == ["done", "done", "failed", "done"]
    assert [row["attempts"] for row in table] == [1, 1, 2, 1]
    assert "coefficientRestitution" in table[2]["error"] and "1.5" in table[2]["error"]
    for row in table:
        if row["status"] == "done":  # the model's damping gives the restitution asked for
            assert row["e"] == pytest.approx(row["restitution"], rel=0.01)
            assert row["pid"] != os.getpid()  # each run in a process of its own
            assert (tmp_path / "study" / f"run{row['run']}" / "pygran.log").is_file()
    assert len({row["pid"] for row in table if "pid" in row}) == 3
    with open(tmp_path / "study" / "results.csv", newline="") as handle:
        written = list(csv.DictReader(handle))
    assert list(written[0]) == ["run", "restitution", "status", "attempts", "seconds", "e", "pid", "error"]
    assert [float(r["e"]) if r["e"] else None for r in written] == [row.get("e") for row in table]
    log = (tmp_path / "study" / "run2" / "study.log").read_text()
    assert log.count("--- study run 2, started") == 2 and "coefficientRestitution" in log


def liggghts_impact(output: Path, restitution: float) -> dict[str, Any]:
    """The same impact on LIGGGHTS, on two MPI ranks of its own."""
    glass = dict(params.glass, coefficientRestitution=restitution)
    dt = simulation.models.HertzMindlin(material=dict(glass, radius=1e-3)).contactTime(SPEED) / 200
    with simulation.DEM(
        engine="liggghts",
        nprocs=2,
        box=(-2e-3, 2e-3, -2e-3, 2e-3, -1e-3, 4e-3),
        boundary=("f", "f", "f"),
        gravity=(0, 0, 0, -1),
        dt=dt,
        output=output,
        species=({"material": glass, "radius": 1e-3},),
    ) as sim:
        sim.setupWall(species=1, wtype="primitive", plane="zplane", peq=0.0)
        sim.createParticles(1, "single", 0.0, 0.0, 1e-3 + 0.5 * SPEED * dt, vel=(0, 0, -SPEED))
        sim.run(600)
        return {"e": sim.extractVelocities()[0, 2] / SPEED}


def test_liggghts_runs_on_their_own_ranks(tmp_path: Path, client: Any) -> None:
    engines = registry.available("engine")
    if "liggghts" not in engines:
        if in_ci():
            pytest.fail("CI=true and the liggghts engine is not installed")
        pytest.skip("the liggghts engine is not installed: pip install ./plugins/pygran-liggghts")
    require_solver(engines["liggghts"].spec.locate_solver)
    rows = grid(restitution=[0.4, 0.8])
    table = Study(liggghts_impact, parameters=rows, output=tmp_path / "study", client=client).run()
    assert [row["e"] for row in table] == pytest.approx([0.4, 0.8], rel=0.01)
    for i in range(2):
        assert (
            "1 by 1 by 2 MPI processor grid" in (tmp_path / "study" / f"run{i}" / "liggghts.log").read_text()
        )


def test_a_killed_study_resumes_from_its_journal(tmp_path: Path, client: Any) -> None:
    script = tmp_path / "impact.py"
    script.write_text(SCRIPT)
    rows = [{**row, "slow": i == 3} for i, row in enumerate(ROWS)]
    folder = tmp_path / "study"
    driver = tmp_path / "driver.py"
    driver.write_text(
        textwrap.dedent(f"""
        from pygran_core.simulation.study import Study

        if __name__ == "__main__":  # Dask's worker processes import this script too
            Study({str(script)!r}, parameters={rows!r}, output={str(folder)!r}, workers=2, retries=0).run()
        """)
    )
    study = subprocess.Popen([sys.executable, str(driver)], start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not _finished(folder, 3) and time.monotonic() < deadline and study.poll() is None:
            time.sleep(0.05)
        assert _finished(folder, 3), "the study did not get through its first three runs"
        slow = int(_wait_for(folder / "run3" / "pid"))
        with pytest.raises(ConfigError, match="another study is running"):
            Study(script, parameters=rows, output=folder, client="serial", resume=True).run()
    finally:
        os.killpg(study.pid, signal.SIGKILL)  # the driver, its scheduler and its workers
        study.wait()
    assert _gone(slow), "the run a killed study was waiting for outlived it"
    journal = json.loads((folder / "study.json").read_text())  # whole: written atomically
    assert [journal["runs"][k]["status"] for k in "0123"] == ["done", "done", "failed", "pending"]

    with pytest.raises(ConfigError, match="resume=True"):
        Study(script, parameters=rows, output=folder, client=client)
    with pytest.raises(ConfigError, match="run 1 ran with"):
        Study(script, parameters=[rows[0], rows[0]], output=folder, client=client, resume=True)
    (folder / "gate").touch()
    more = [*rows, {"restitution": 0.45, "slow": False}]  # a row added to the study
    with pytest.warns(PyGranWarning, match="1 of 5 runs failed"):
        table = Study(script, parameters=more, output=folder, client=client, retries=0, resume=True).run()
    assert [row["status"] for row in table] == ["done", "done", "failed", "done", "done"]
    for row in table:
        if row["status"] == "done":
            assert row["e"] == pytest.approx(row["restitution"], rel=0.01)
    starts = [(folder / f"run{i}" / "study.log").read_text().count("started") for i in range(5)]
    assert starts == [1, 1, 2, 2, 1]  # finished runs skipped; the failed and killed ones again


def _finished(folder: Path, count: int) -> bool:
    try:
        runs = json.loads((folder / "study.json").read_text())["runs"]
    except (OSError, ValueError):
        return False
    return sum(entry["status"] in ("done", "failed") for entry in runs.values()) >= count


def _wait_for(path: Path) -> str:
    deadline = time.monotonic() + 30
    while not (path.is_file() and path.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    return path.read_text()


def _gone(pid: int) -> bool:
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_serial_studies_need_no_dask(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    script = tmp_path / "impact.py"
    script.write_text(SCRIPT)
    monkeypatch.setitem(sys.modules, "distributed", None)
    rows = grid(restitution=[0.5, 0.8], slow=[False])
    assert rows == [{"restitution": 0.5, "slow": False}, {"restitution": 0.8, "slow": False}]
    table = Study(script, parameters=rows, output=tmp_path / "serial", client="serial").run()
    assert [row["e"] for row in table] == pytest.approx([0.5, 0.8], rel=0.01)
    with pytest.raises(UnsupportedFeature, match=r"pip install pygran-core\[dask\]"):
        Study(script, parameters=rows, output=tmp_path / "local").run()
    slow = [{"restitution": 0.5, "slow": True}]  # waits for a gate that never opens
    with pytest.warns(PyGranWarning, match=r"after 1 attempt: run 0 \(timed out after 4 s"):
        (row,) = Study(
            script, parameters=slow, output=tmp_path / "slow", client="serial", timeout=4, retries=0
        ).run()
    assert row["status"] == "failed" and row["attempts"] == 1 and 4 <= row["seconds"] < 6
    assert _gone(int((tmp_path / "slow" / "run0" / "pid").read_text()))
    (tmp_path / "blocked").mkdir()
    (tmp_path / "blocked" / "run0").write_text("a file where the run's folder goes")
    with pytest.warns(PyGranWarning, match="could not start"):
        (row,) = Study(script, parameters=slow, output=tmp_path / "blocked", client="serial", retries=0).run()
    assert row["status"] == "failed" and "File exists" in row["error"]


def test_mistakes_are_refused_before_anything_runs(tmp_path: Path) -> None:
    columns = {"restitution": [0.3, 0.5], "material": [params.glass, params.steel]}
    assert rows_of(columns) == [
        {"restitution": 0.3, "material": params.glass},
        {"restitution": 0.5, "material": params.steel},
    ]
    out = tmp_path / "never"
    with pytest.raises(ConfigError, match="does not fit"):
        Study(impact, parameters=[{"restitution": 0.5, "radius": 1e-3}], output=out, client="serial")
    with pytest.raises(ConfigError, match="one length"):
        Study(impact, parameters={"restitution": [0.3, 0.5], "speed": [1.0]}, output=out, client="serial")
    with pytest.raises(ConfigError, match="reserved"):
        Study(impact, parameters=[{"status": 1}], output=out, client="serial")
    with pytest.raises(ConfigError, match="JSON"):
        Study(impact, parameters=[{"restitution": object()}], output=out, client="serial")
    with pytest.raises(ConfigError, match="not a Python script"):
        Study(tmp_path / "missing.py", parameters=ROWS, output=out, client="serial")
    with pytest.raises(ConfigError, match="runs here"):
        Study(impact, parameters=ROWS, output=out, client="serial", workers=2)
    with pytest.raises(ConfigError, match="retries"):
        Study(impact, parameters=ROWS, output=out, client="serial", retries=-1)
    with pytest.raises(ConfigError, match="not running inside a Study"):
        current()
    assert not out.exists()
