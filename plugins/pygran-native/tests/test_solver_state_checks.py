"""A damaged native checkpoint state is a ReadError naming the entry, never a crash.

The state of a real run (a periodic bed on a plane, beside a cylinder and a moving mesh, with
contacts and wall contacts) is damaged one entry at a time: longer, shorter, another dtype,
out-of-range values, offsets that are not monotone, undecodable text. ``Solver.set_state``
must refuse each with :class:`ReadError` and leave the solver able to run on as before. The
damaged states are restored in a child process, so heap corruption fails the test instead of
killing pytest.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pygran_core.errors import ReadError

R, RHO = 1e-3, 2500.0

SETUP = """
import numpy as np
from pygran_native.solver import Solver

R, RHO = 1e-3, 2500.0


def make(threads=2):
    a = 2.2e-3
    s = Solver(box=[[0, 0, 0], [5 * a, 5 * a, 8 * a]], periodic=(True, True, False),
               gravity=(0, 0, -9.81), skin=4e-4, threads=threads, seed=7)
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.3, friction=0.5,
                        rolling_friction=0.02)
    return s


def real_state():
    s = make()
    s.add_plane((0, 0, 0), (0, 0, 1))
    s.add_cylinder("z", (5.5e-3, 5.5e-3), 0.1)
    plate = s.add_mesh([[0, 0, 0.016], [0.011, 0, 0.016], [0, 0.011, 0.016]], [[0, 1, 2]])
    s.set_mesh_motion(plate, velocity=(0, 0, 0.01))
    grid = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(3)
    s.add_particles((grid + 0.5) * 2.2e-3 + rng.uniform(-1e-4, 1e-4, grid.shape), R, densities=RHO)
    s.run(1500, 1e-5)
    return s, s.get_state()
"""


def mutations(state: dict[str, np.ndarray]) -> dict[str, tuple[str, dict[str, np.ndarray]]]:
    """Damaged copies of ``state``: name -> (the entry the error must name, the state)."""
    out: dict[str, tuple[str, dict[str, np.ndarray]]] = {}

    def put(name, key, value, named=None):
        out[name] = (named or key, {**state, key: value})

    other = {"f": np.float32, "i": np.int64, "u": np.int32}
    for key, value in state.items():
        if value.ndim == 0:
            continue
        if key != "core_bounds":  # longer bounds ending at n are those of another thread count
            extra = value[-1:] if len(value) else np.zeros(1, value.dtype)
            put(f"{key} longer", key, np.concatenate([value, extra]))
        if len(value):
            put(f"{key} shorter", key, value[:-1])
        put(
            f"{key} dtype",
            key,
            value.astype(np.int32 if value.dtype == np.int64 else other[value.dtype.kind]),
        )
        put(f"{key} 2-d", key, value[None])
    missing = dict(state)
    del missing["core_nb_j"]
    out["nb_j missing"] = ("core_nb_j", missing)
    n = len(state["core_r"])
    ne = len(state["core_ekind"])

    def changed(key, index, value, named=None, name=None):
        arr = state[key].copy()
        arr[index] = value
        put(name or f"{key}[{index}] = {value}", key, arr, named)

    nb_start = state["core_nb_start"]
    row = int(np.argmax(np.diff(nb_start) > 0))  # a row with partners
    changed("core_nb_j", nb_start[row], n, name="partner beyond the particles")
    changed("core_nb_j", nb_start[row], row, name="partner j = i")
    changed("core_nb_j", nb_start[row], -1, name="negative partner")
    changed("core_nb_start", 0, 1, name="offsets not from 0")
    changed("core_nb_start", n, nb_start[n] - 1, name="offsets short of the list")
    changed("core_nb_start", row + 1, nb_start[row + 1] + 10**6, name="offsets not monotone")
    changed("core_nb_s", 0, 27, name="image code 27")
    changed("core_nb_s", 0, 0x20 | 13, name="unknown flag bit")
    changed("core_nb_s", 0, 13 + 1, name="image across the fixed z axis")
    wl = state["core_wl_start"]
    changed("core_wl_start", 1, wl[n] + 5, name="wall offsets not monotone")
    changed("core_wl_e", 0, ne, name="wall element beyond the elements")
    wl_h = state["core_wl_h"].copy().reshape(len(state["core_wl_e"]), -1)
    wl_h[0, -1] = 7.0
    put("plane side 7", "core_wl_h", wl_h.reshape(-1))
    changed("core_type", 0, 1, name="type beyond the model's types")
    changed("core_r", 0, -R, name="negative radius")
    changed("core_r", 0, np.nan, name="radius NaN")
    changed("core_m", 0, 0.0, name="zero mass")
    changed("core_id", 1, state["core_id"][0], name="repeated id")
    changed("core_ekind", 0, 5, name="element kind 5")
    changed("core_etype", 0, 3, name="element type beyond the types")
    changed("core_ewall", 0, 99, name="element of no wall")
    changed("core_ewall", 0, int(state["core_ewall"][-1]), name="plane element of the mesh")
    changed("core_emoving", 0, 2, name="moving flag 2")
    cylinder = int(np.flatnonzero(state["core_ekind"] == 1)[0])
    changed("core_egeo", 9 * cylinder, 3.0, name="cylinder axis 3")
    changed("core_egeo", 9 * cylinder + 3, -1.0, name="cylinder radius < 0")
    changed("core_emot", 0, np.inf, name="infinite wall velocity")
    changed("core_bounds", 1, n + 1, name="block bounds beyond the particles")
    changed("core_bounds", 0, 3, name="block bounds not from 0")
    changed("core_counters", 3, 2, name="dirty flag 2")
    changed("core_counters", 0, -1, name="negative step")
    changed("core_scalars", 0, np.nan, name="time NaN")
    changed("core_visc", 0, -1.0, name="negative damping")
    changed("counters", 0, 0, name="next id among those in use")
    changed("wall_kinds", 0, 3, name="wall kind 3")
    changed("wall_handles", 0, 1, name="repeated wall handle")
    put("model kind not UTF-8", "model_kind", np.frombuffer(b"\xffhertz", np.uint8).copy())
    put("model kind unknown", "model_kind", np.frombuffer(b"herz", np.uint8).copy())
    put("model youngs negative", "model_youngs", np.array(-1.0))
    put("model youngs as text", "model_youngs", np.frombuffer(b"5e6", np.uint8).copy())
    put("rng not JSON", "rng", np.frombuffer(b'{"state": ', np.uint8).copy())
    put("rng not UTF-8", "rng", np.frombuffer(b"\xfe\xff", np.uint8).copy())
    put("rng of another generator", "rng", np.frombuffer(b'{"bit_generator": "MT19937"}', np.uint8).copy())
    return out


CHILD = SETUP + textwrap.dedent(
    """
    import json, sys
    from pygran_core.errors import ReadError
    sys.path.insert(0, sys.argv[1])
    from test_solver_state_checks import mutations

    source, state = real_state()
    source.run(500, 1e-5)
    expected = [source.positions, source.velocities, source.omegas]
    target, _ = real_state()
    results = {}
    for name, (key, damaged) in mutations(state).items():
        try:
            target.set_state(damaged)
            results[name] = ["accepted", key, ""]
        except Exception as exc:
            results[name] = [type(exc).__name__, key, str(exc)]
    target.set_state(state)  # the solver still takes a good state and runs on bitwise
    target.run(500, 1e-5)
    now = [target.positions, target.velocities, target.omegas]
    same = all(np.array_equal(a, b) for a, b in zip(expected, now))
    print(json.dumps({"results": results, "same": same, "count": len(results)}))
    """
)


def test_every_damaged_entry_is_a_read_error_naming_it(tmp_path):
    here = str(__import__("pathlib").Path(__file__).parent)
    done = subprocess.run(
        [sys.executable, "-c", CHILD, here], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.splitlines()[-1])
    results = report["results"]
    assert report["count"] > 150  # every array 4 ways, and 45 targeted damages
    wrong = {name: r for name, r in results.items() if r[0] != "ReadError" or r[1] not in r[2]}
    assert not wrong, wrong
    assert report["same"]  # refusals changed nothing: the good state then runs on bitwise


def test_a_longer_position_array_is_refused_before_anything_is_copied():
    namespace: dict = {}
    exec(SETUP, namespace)
    solver, state = namespace["real_state"]()
    before = solver.get_state()
    longer = np.concatenate([state["core_x"], np.ones(3000)])
    with pytest.raises(
        ReadError, match=r"'core_x': expected 375 values \(3 per particle of core_r\), found 3375"
    ):
        solver.set_state({**state, "core_x": longer})
    with pytest.raises(ReadError, match="missing entry 'rng'"):
        solver.set_state({k: v for k, v in state.items() if k != "rng"})
    after = solver.get_state()
    assert all(np.array_equal(before[k], after[k], equal_nan=True) for k in before)


def test_a_resume_from_a_damaged_checkpoint_names_the_file(tmp_path):
    from pygran_core import simulation
    from pygran_core.simulation.checkpoint import read_checkpoint, write_checkpoint
    from pygran_core.simulation.models import HertzMindlin

    material = {"youngsModulus": 1e6, "poissonsRatio": 0.3, "coefficientRestitution": 0.5, "density": 1000.0}

    def study(resume: bool) -> None:
        with simulation.DEM(
            engine="native",
            model=HertzMindlin,
            box=(0, 4e-3, 0, 4e-3, 0, 4e-3),
            gravity=(9.81, 0, 0, -1),
            dt=1e-6,
            output=str(tmp_path / "out"),
            progress=False,
            species=({"material": material, "radius": 2e-4},),
            traj={"pfile": None},
            restart=(500, "restart", "restart.h5", resume),
            threads=1,
        ) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            sim.createParticles(1, "single", 2e-3, 2e-3, 1e-3)
            sim.run(1000)

    study(False)
    path = tmp_path / "out" / "restart" / "restart.h5"
    checkpoint = read_checkpoint(path)
    checkpoint.state["solver/core_x"] = np.zeros(30)
    write_checkpoint(path, checkpoint)
    with pytest.raises(
        ReadError, match=rf"{path}: .*'core_x': expected 3 values \(3 per particle of core_r\), found 30"
    ):
        study(True)


def test_a_state_taken_between_adding_particles_and_running_is_accepted():
    """Particles added since the last run (lists and block bounds to be made anew: the bounds
    still end at the old count) restore and continue bitwise."""
    namespace: dict = {}
    exec(SETUP, namespace)
    solver, _ = namespace["real_state"]()
    solver.add_particles([[2e-3, 2e-3, 0.013]], R, densities=RHO)
    state = solver.get_state()
    assert state["core_bounds"][-1] < len(state["core_r"])
    restored = namespace["make"]()
    restored.set_state(state)
    for s in (solver, restored):
        s.run(300, 1e-5)
    np.testing.assert_array_equal(solver.positions, restored.positions)
