"""Contact output as the Engine base class schedules it (``traj`` ``cfile``): a contacts frame
beside each particle frame, in a dump local file or in the particle H5MD file; read back by
``analysis.System`` in step with the particles; cut back on resume; refused by an engine
without the capability ``contact-output``. The engine here makes contacts that depend on the
step only, so every record written is known."""

from __future__ import annotations

import numpy as np
import pytest

from pygran_core import Engine
from pygran_core.analysis.system import System
from pygran_core.errors import ConfigError, EngineError, UnsupportedFeature
from pygran_core.simulation.models import SpringDashpot
from pygran_core.simulation.specs import parse_simulation


def contacts_at(step: int) -> dict[str, np.ndarray]:
    """``step // 500 % 4`` contacts between particles 1..3, the last with wall 0."""
    n = step // 500 % 4
    k = np.arange(n, dtype=float)
    return {
        "id1": np.arange(1, n + 1),
        "id2": np.array([*range(2, n + 1), -1][:n]),
        "fx": step + k,
        "fy": -k,
        "fz": k / 3,
        "cx": k,
        "cy": k + 0.5,
        "cz": np.full(n, 1e-3),
        "bx": -k,
        "by": k * 1e-4,
        "bz": np.zeros(n),
    }


class ContactEngine(Engine):
    name = "contacting"
    capabilities = frozenset({"spring-dashpot", "contact-output", "restart"})

    def __init__(self, output, crash_at=None, **params):
        params = {"box": (0, 1, 0, 1, 0, 1), "output": str(output), "dt": 1e-5, "progress": False, **params}
        super().__init__(parse_simulation(params, self.name, SpringDashpot))
        self.crash_at = crash_at

    def _advance(self, nsteps):
        if self.crash_at is not None and self.step + nsteps > self.crash_at:
            raise EngineError("the solver crashed")

    def _extract(self, quantity):
        values = {"id": np.arange(1, 4), "type": np.ones(3, int), "radius": np.full(3, 1e-3)}
        return values.get(quantity, np.full((3, 3), self.step * 1e-6))

    def _contacts(self):
        return contacts_at(self.step)


class PlainEngine(ContactEngine):
    name = "plain"
    capabilities = frozenset({"spring-dashpot"})


TRAJ = {"freq": 500, "args": ("id", "type", "x", "y", "z", "radius")}


def check_in_step(system: System, steps: list[int]) -> None:
    """Every frame's contacts are those of its step, at the particles' timestep."""
    assert len(system) == len(steps)
    for _frame, step in zip(system.frames(), steps):
        assert system.Particles.timestep == system.Contacts.timestep == step
        expected = contacts_at(step)
        assert len(system.Contacts) == len(expected["id1"])
        for name, values in expected.items():
            np.testing.assert_array_equal(getattr(system.Contacts, name), values, err_msg=f"{name} at {step}")


def test_dump_local_beside_a_dump(tmp_path):
    with ContactEngine(tmp_path, traj={**TRAJ, "pfile": "traj*.dump", "cfile": "contacts*.dump"}) as engine:
        engine.run(2000)
    assert "ITEM: NUMBER OF ENTRIES\n2\n" in (tmp_path / "contacts1500.dump").read_text()  # the pairs
    assert "ITEM: NUMBER OF ENTRIES\n1\n" in (tmp_path / "wall-contacts1500.dump").read_text()
    with System(Particles=str(tmp_path / "traj*.dump"), Contacts=str(tmp_path / "contacts*.dump")) as system:
        check_in_step(system, [0, 500, 1000, 1500, 2000])
        system.goto(3)
        walls = system.Contacts.walls
        assert walls.tolist() == [False, False, True] and system.Contacts.id2[walls].tolist() == [-1]


def test_h5md_particles_and_contacts_in_one_file(tmp_path):
    with ContactEngine(tmp_path, traj={**TRAJ, "pfile": "run.h5", "cfile": "run.h5"}) as engine:
        engine.run(1500)
    with System(Particles=str(tmp_path / "run.h5")) as system:  # the file's contacts, unasked
        assert system.names == ["Particles", "Contacts"]
        check_in_step(system, [0, 500, 1000, 1500])


def test_resume_cuts_the_contacts_back(tmp_path):
    """A run killed after its checkpoint at 1000 and a frame at 1500 resumes at 1000: each
    trajectory keeps its frames up to 1000 and continues, every frame once."""
    for traj in ({"pfile": "run.h5", "cfile": "run.h5"}, {"pfile": "traj.dump", "cfile": "contacts.dump"}):
        out = tmp_path / traj["cfile"].split(".")[1]
        params = {"traj": {**TRAJ, **traj}, "restart": {"freq": 1000}}
        with ContactEngine(out, crash_at=1700, **params) as engine, pytest.raises(EngineError):
            engine.run(3000)
        with ContactEngine(out, **params | {"restart": {"freq": 1000, "resume": True}}) as engine:
            engine.run(3000)
        with System(Particles=str(out / traj["pfile"]), Contacts=str(out / traj["cfile"])) as system:
            check_in_step(system, list(range(0, 3001, 500)))


def test_resume_keeps_the_frames_a_series_index_lists(tmp_path):
    """Particles as a .vtk series: after a resume at 1000 the .pvd index lists every frame
    once, in order, at its step and time (the frames up to 1000 from the first run)."""
    params = {"traj": {**TRAJ, "pfile": "p*.vtk"}, "restart": {"freq": 1000}}
    with ContactEngine(tmp_path, crash_at=1700, **params) as engine, pytest.raises(EngineError):
        engine.run(3000)
    with ContactEngine(tmp_path, **params | {"restart": {"freq": 1000, "resume": True}}) as engine:
        engine.run(3000)
    with System(Particles=str(tmp_path / "p.pvd")) as system:
        assert [system.Particles.timestep for _ in system.frames()] == list(range(0, 3001, 500))
        assert [system.Particles.time for _ in system.frames()] == [
            step * 1e-5 for step in range(0, 3001, 500)
        ]


def test_refused_without_the_capability(tmp_path):
    with pytest.raises(UnsupportedFeature, match="contact output.*'contact-output'"):
        PlainEngine(tmp_path / "asked", traj={"cfile": "contacts.dump"})
    with PlainEngine(tmp_path / "plain", traj=TRAJ) as engine:  # nothing asked: nothing refused
        engine.run(10)


@pytest.mark.parametrize(
    ("traj", "message"),
    [
        ({"cfile": "contacts.txt"}, "contact records are written as a .dump"),
        ({"pfile": "traj.dump", "cfile": "traj.dump"}, "holds particles or contacts, not both"),
    ],
)
def test_bad_contact_file_names(tmp_path, traj, message):
    with pytest.raises(ConfigError, match=message):
        ContactEngine(tmp_path, traj=traj)
