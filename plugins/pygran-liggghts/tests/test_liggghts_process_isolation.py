"""From plain Python, LIGGGHTS stays out of the user's process: listing the plugins and the
engines' capabilities and running a LIGGGHTS and a native simulation map no libliggghts and
none of Debian's VTK 9.1 libraries it is linked to, so pip's VTK (pyvista) then works in the
same script. The script runs in a process of its own, so that a crash cannot take the test
runner with it."""

import importlib.util
import json
import subprocess
import sys
import textwrap

import pytest
from pygran_liggghts import library
from pygran_liggghts.library import find_library

from pygran_core.testing.solvers import in_ci, require_solver

#: A user's script: the plugins and capabilities listed, a LIGGGHTS and a native run of a falling
#: sphere, then a VTK file written and read back with pyvista; it prints its results as JSON.
SCRIPT = textwrap.dedent(
    """
    import json, re, sys
    from pathlib import Path
    from pygran_core import cli, registry, simulation
    from pygran_core.testing.validation import SOFT

    out = Path(sys.argv[1])
    cli.main(["plugins"])
    capabilities = {name: sorted(p.spec.capabilities) for name, p in registry.available("engine").items()}
    heights = {}
    for engine in ("liggghts", "native"):
        with simulation.DEM(engine=engine, model="HertzMindlin", box=(-0.01, 0.01, -0.01, 0.01, 0, 0.02),
                            dt=1e-5, gravity=(9.81, 0, 0, -1), output=str(out / engine),
                            species=({"material": SOFT, "radius": 1e-3},), traj={"pfile": None},
                            progress=False) as sim:
            sim.createParticles(1, "single", 0.0, 0.0, 0.01)
            sim.run(100)
            heights[engine] = float(sim.extractCoords()[0, 2])

    import pyvista as pv

    sphere = pv.Sphere()
    sphere.save(out / "sphere.vtk")
    points = pv.read(out / "sphere.vtk").n_points
    maps = Path("/proc/self/maps").read_text().splitlines()
    mapped = sorted({line.split()[-1] for line in maps if re.search(r"libliggghts|libvtk[^/]*9\\.1", line)})
    print(json.dumps({"capabilities": capabilities, "heights": heights, "points": points,
                      "expected_points": sphere.n_points, "mapped": mapped}))
    """
)


def test_plain_python_keeps_liggghts_out_of_the_process(tmp_path):
    require_solver(find_library)
    if importlib.util.find_spec("pyvista") is None:
        message = "pyvista is not installed (pip install pyvista)"
        if in_ci():
            pytest.fail(f"CI=true and {message}", pytrace=False)
        pytest.skip(message)
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "liggghts" in done.stdout.split("engines:")[1]  # `pygran plugins` listed the engine
    result = json.loads(done.stdout.splitlines()[-1])
    assert result["mapped"] == []
    assert "mpi" in result["capabilities"]["liggghts"]
    assert result["points"] == result["expected_points"]
    fall = 0.5 * 9.81 * (100 * 1e-5) ** 2
    for engine, height in result["heights"].items():
        assert height == pytest.approx(0.01 - fall, rel=1e-6, abs=1e-9), engine
    assert (tmp_path / "liggghts" / "liggghts.log").is_file()  # LIGGGHTS ran, in its worker


def test_a_probe_that_fails_is_the_reason(monkeypatch, caplog):
    """A probe process that dies leaves ThorntonNing unavailable, with its status and error."""
    monkeypatch.setattr(library, "PROBE", "import sys; sys.exit('no luck')")
    addon = library.probe_addon.__wrapped__()
    assert not addon.loaded and "ended with status 1: no luck" in addon.reason
    assert addon.reason in caplog.text
