"""The engine suite's check of checkpoints: a script resumed from one ends where it ended."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pygran_core.errors import UnsupportedFeature
from pygran_core.testing.engines.base import GRAVITY, RADIUS, EngineSuite, create


class RestartChecks(EngineSuite):
    """Checkpoints and resume: a restart round trip."""

    def restart_script(self, output: Path, resume: bool = False, lastfile: str | None = None) -> dict:
        """A sphere sliding on a floor (friction history), one bouncing, one falling onto it;
        checkpoints every 250 steps; its final state and monitor."""
        restart = (250, "restart", "restart.*.h5", resume, lastfile)
        x = np.array([[-4e-3, 0.0, RADIUS], [4e-3, 0.0, 1.1e-3], [4e-3, 0.0, 3.3e-3]])
        keywords: dict[str, Any] = {
            "dt": self.dt(),
            "gravity": GRAVITY,
            "box": (-6e-3, 6e-3, -6e-3, 6e-3, 0.0, 8e-3),
        }
        with self.dem(output, restart=restart, **keywords) as sim:
            sim.setupWall(species=1, plane="zplane", peq=0.0)
            sim.createParticles(1, "single", *x[0], vel=(0.05, 0.0, 0.0))
            create(sim, x[1:])
            ke = sim.monitor(quantities=("ke",), freq=50, file="ke.txt")
            sim.run(500)
            sim.run(500)
            return {
                "x": sim.extractCoords(),
                "v": sim.extractVelocities(),
                "omega": sim.extractOmegas(),
                "ke": ke.values["ke"],
                "step": sim.step,
            }

    def test_restart_round_trip(self, tmp_path):
        """Resumed from its checkpoint at step 750, the script ends where it ended uninterrupted."""
        if not self.supports("restart"):
            with pytest.raises(UnsupportedFeature):
                self.dem(tmp_path, restart=(250, "restart", "restart.h5")).close()
            return
        straight = self.restart_script(tmp_path)
        assert (tmp_path / "restart" / "restart.750.h5").is_file()
        again = self.restart_script(tmp_path, resume=True, lastfile="restart.750.h5")
        assert again["step"] == straight["step"] == 1000
        assert "resumed from" in (tmp_path / "pygran.log").read_text()
        for key in ("x", "v", "omega", "ke"):
            np.testing.assert_allclose(again[key], straight[key], rtol=1e-9, atol=1e-15, err_msg=key)
