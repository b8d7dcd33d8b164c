"""The pygran command."""

import subprocess
import sys
from pathlib import Path

PYGRAN = str(Path(sys.executable).with_name("pygran"))


def test_version():
    out = subprocess.run([PYGRAN, "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "pygran 0.1.0"


def test_plugins_lists_every_plugin_with_distribution():
    out = subprocess.run([PYGRAN, "plugins"], capture_output=True, text=True, check=True).stdout
    for line in (
        "native           pygran-native 0.1.0",
        "liggghts         pygran-liggghts 0.1.0",
        "yade             pygran-yade 0.1.0",
        "readers          pygran-readers 0.1.0",
    ):
        assert line in out
    assert "HertzMindlin" in out and "pygran-core 0.1.0" in out
    assert "solver: compiled kernels" in out


def test_no_command_is_a_usage_error():
    out = subprocess.run([PYGRAN], capture_output=True, text=True)
    assert out.returncode == 2 and "usage: pygran" in out.stderr


def test_validate_prints_a_table_and_exits_zero_when_every_check_passes():
    out = subprocess.run(
        [PYGRAN, "validate", "--engine", "native", "--check", "hertz"], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stdout + out.stderr
    rows = out.stdout.splitlines()
    assert rows[0].split()[:4] == ["check", "expected", "obtained", "tolerance"]
    assert [r.split()[0:3] for r in rows[1:3]] == [["Hertz", "contact", "time"], ["Hertz", "max", "overlap"]]
    assert all(" pass" in r for r in rows[1:3])
    assert rows[3] == "2 passed, 0 failed, 0 unsupported on the native engine"


def test_validate_rejects_unknown_checks():
    out = subprocess.run([PYGRAN, "validate", "--check", "hertzz"], capture_output=True, text=True)
    assert out.returncode == 2 and "invalid choice: 'hertzz'" in out.stderr
