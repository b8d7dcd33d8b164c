"""Common engine behaviour owned by the Engine base class."""

import logging

import numpy as np
import pytest

from pygran_core import Engine
from pygran_core.errors import ConfigError, EngineError, UnsupportedFeature
from pygran_core.simulation.calls import parse_monitor
from pygran_core.simulation.models import SpringDashpot
from pygran_core.simulation.output import particle_frame
from pygran_core.simulation.specs import parse_simulation


class CountingEngine(Engine):
    name = "counting"
    capabilities = frozenset({"periodic", "spring-dashpot"})

    def __init__(self, output, **params):
        params = {"box": (0, 1, 0, 1, 0, 1), "output": str(output), "traj": {"pfile": None}, **params}
        super().__init__(parse_simulation(params, "counting", SpringDashpot))
        self.chunks = []
        self.removed = []
        self.released = 0

    def _advance(self, nsteps):
        self.chunks.append(nsteps)

    def _extract(self, quantity):
        return np.zeros((2, 3)) if quantity in ("x", "v") else np.arange(2)

    def _remove(self, handle):
        self.removed.append(handle.label)

    def _close(self):
        self.released += 1


def test_output_directory_created_without_chdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    engine = CountingEngine("nested/out", progress=False)
    assert engine.output == tmp_path / "nested" / "out"
    assert engine.output.is_dir()
    assert (engine.output / "pygran.log").is_file()
    import os

    assert os.getcwd() == str(tmp_path)
    engine.close()


def test_run_splits_into_chunks_and_counts_time(tmp_path):
    engine = CountingEngine(tmp_path, dt=1e-3, progress=False)
    engine.run(1050)
    assert sum(engine.chunks) == 1050 and len(engine.chunks) == 100
    assert max(engine.chunks) - min(engine.chunks) <= 1
    engine.run(7, dt=1e-4)
    assert engine.chunks[-7:] == [1] * 7
    assert engine.step == 1057
    assert engine.time == pytest.approx(1050 * 1e-3 + 7 * 1e-4)
    engine.close()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((0,), "nsteps must be a positive integer"),
        ((10.5,), "nsteps must be a positive integer"),
        ((10, -1.0), "dt must be a positive number"),
        ((True,), "nsteps must be a positive integer"),
    ],
)
def test_run_rejects_bad_arguments(tmp_path, args, message):
    with (
        CountingEngine(tmp_path, dt=1e-3, progress=False) as engine,
        pytest.raises(ConfigError, match=message),
    ):
        engine.run(*args)


def test_run_without_time_step_says_how(tmp_path):
    with CountingEngine(tmp_path, progress=False) as engine, pytest.raises(ConfigError, match="No time step"):
        engine.run(10)


def test_handles_remove_once(tmp_path):
    engine = CountingEngine(tmp_path, progress=False)
    first, second = engine._new_handle("wall", "w1"), engine._new_handle("insertion", "ins1")
    assert engine.handles == (first, second)
    engine.remove(first)
    assert engine.removed == ["w1"] and engine.handles == (second,)
    with pytest.raises(ConfigError, match="already removed"):
        engine.remove(first)
    other = CountingEngine(tmp_path / "other", progress=False)
    with pytest.raises(ConfigError, match="not a handle returned by this simulation"):
        other.remove(second)
    engine.close()
    other.close()


def test_close_is_idempotent_and_final(tmp_path):
    with CountingEngine(tmp_path, dt=1e-3, progress=False) as engine:
        pass
    engine.close()
    assert engine.released == 1
    with pytest.raises(EngineError, match="closed"):
        engine.run(1)


def test_every_call_logged_to_file_not_console(tmp_path, caplog):
    with caplog.at_level(logging.WARNING), CountingEngine(tmp_path, dt=1e-3, progress=False) as engine:
        engine.run(10)
    text = (tmp_path / "pygran.log").read_text()
    assert "counting engine opened" in text
    assert "run 10 steps of dt=0.001 from step 0" in text
    assert "counting engine closed at step 10" in text
    assert not caplog.records


def test_two_engines_log_to_their_own_files(tmp_path):
    a = CountingEngine(tmp_path / "a", dt=1e-3, progress=False)
    b = CountingEngine(tmp_path / "b", dt=1e-3, progress=False)
    a.run(3)
    b.run(5)
    a.close()
    b.close()
    assert "run 3 steps" in (tmp_path / "a" / "pygran.log").read_text()
    assert "run 3 steps" not in (tmp_path / "b" / "pygran.log").read_text()


def test_progress_bar_shown_when_asked(tmp_path, capsys):
    with CountingEngine(tmp_path, dt=1e-3) as engine:
        engine.run(200, progress=True)
    assert "200/200" in capsys.readouterr().err


def test_unsupported_capability_message(tmp_path):
    with CountingEngine(tmp_path, progress=False) as engine:
        engine.require("periodic")
        with pytest.raises(UnsupportedFeature, match="counting engine does not support mesh walls"):
            engine.require("mesh-walls", "mesh walls")


def test_spec_needing_a_missing_capability_is_refused_at_once(tmp_path):
    with pytest.raises(UnsupportedFeature, match="does not support restart files"):
        CountingEngine(tmp_path, restart=100)


def test_events_split_the_run_and_monitors_sample(tmp_path):
    engine = CountingEngine(tmp_path, dt=1e-3, progress=False)
    engine.max_run_chunks = 1
    monitor = engine.monitor(parse_monitor({"freq": 30, "quantities": ("n", "time")}))
    engine.run(100)
    assert engine.chunks == [30, 30, 30, 10]
    np.testing.assert_array_equal(monitor.values["step"], [0, 30, 60, 90])
    np.testing.assert_array_equal(monitor.values["n"], [2, 2, 2, 2])
    np.testing.assert_allclose(monitor.values["time"], [0, 0.03, 0.06, 0.09])
    assert (tmp_path / "monitor.txt").read_text().splitlines()[0] == "# step time n time"
    engine.remove(monitor)
    engine.run(40)
    assert len(monitor.values["step"]) == 4
    engine.close()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("id", "x", "radiuss"), r"unknown column\(s\) \['radiuss'\]. Did you mean 'radius'?"),
        ("id type radiuss", r"unknown column\(s\) \['radiuss'\]. Did you mean 'radius'?"),
        (list("id"), r"unknown column\(s\) \['i', 'd'\]. A string was split into letters"),
    ],
)
def test_unknown_trajectory_columns_are_refused(tmp_path, args, message):
    with pytest.raises(ConfigError, match="traj args: " + message):
        CountingEngine(tmp_path, traj={"pfile": "traj.dump", "args": args})


def test_trajectory_columns_as_one_string_as_liggghts_takes_them(tmp_path):
    engine = CountingEngine(tmp_path, traj={"pfile": "traj.dump", "args": "id type  x y z"})
    assert engine.spec.traj.args == ("id", "type", "x", "y", "z")
    engine.close()


def test_trajectory_frames_hold_the_selected_species_in_the_given_order(tmp_path):
    columns = ("x", "type", "id", "vz")
    with CountingEngine(tmp_path, traj={"pfile": None, "args": columns, "sel": 1}) as engine:
        frame = particle_frame(engine.spec, engine._extract, engine.step, engine.time)
        assert tuple(frame.arrays) == columns
        np.testing.assert_array_equal(frame.arrays["type"], [1])  # of types 0 and 1
        np.testing.assert_array_equal(frame.arrays["id"], [1])


def test_set_refuses_ids_no_particle_has(tmp_path):
    from pygran_core.simulation.calls import parse_set

    with CountingEngine(
        tmp_path, species=({"material": {"youngsModulus": 1e7, "density": 1e3}, "radius": 1e-3},)
    ) as engine:
        request = parse_set({"ids": (1, 99), "vel": (0, 0, 1)}, engine.spec)
        with pytest.raises(
            ConfigError, match=r"set/velocity ids: no particle has id 99 \(the simulation has 2"
        ):
            engine.set_properties(request)
        assert engine.journal.calls == []  # refused before anything was recorded
