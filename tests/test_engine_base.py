"""Common engine behaviour owned by the Engine base class."""

import logging

import pytest

from pygran_core import Engine
from pygran_core.errors import ConfigError, EngineError, UnsupportedFeature


class CountingEngine(Engine):
    name = "counting"
    capabilities = frozenset({"periodic"})

    def __init__(self, output, **options):
        super().__init__(output, **options)
        self.chunks = []
        self.removed = []
        self.released = 0

    def _advance(self, nsteps):
        self.chunks.append(nsteps)

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
