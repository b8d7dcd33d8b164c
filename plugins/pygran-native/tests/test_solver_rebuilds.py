"""When the neighbour lists are rebuilt: at the first step after which a particle is more than
half the skin from where the last rebuild left it, never earlier or later. A drift measures
each particle's displacement only when its speeds cannot prove that none is due (State.travel);
when the speeds rise past what it planned for, a pass of its own measures them. Here free
spheres (no gravity, no contacts) drift at set speeds, sometimes sped up between runs, and a
numpy replica of the rule gives the rebuilds and the positions to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from pygran_native.solver import Solver

R, SKIN, DT, SIDE = 1e-3, 2e-4, 1e-5, 0.2


class Replica:
    """Free spheres' drifts (x += dt v, as the solver rounds it) and the rebuild rule."""

    def __init__(self, x: np.ndarray, v: np.ndarray) -> None:
        self.x, self.v = x.copy(), v.copy()
        self.x0, self.rebuilds = x.copy(), 1  # the first run starts with a rebuild

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.x = self.x + DT * self.v
            q = self.x - self.x0
            dd = ((0.0 + q[:, 0] * q[:, 0]) + q[:, 1] * q[:, 1]) + q[:, 2] * q[:, 2]
            if np.sqrt(dd.max()) > 0.5 * SKIN:
                self.x0, self.rebuilds = self.x.copy(), self.rebuilds + 1


@pytest.mark.parametrize("threads", [1, 2])
def test_lists_are_rebuilt_at_the_first_step_past_half_the_skin(threads):
    rng = np.random.default_rng(11)
    x = (np.indices((6, 6, 6)).reshape(3, -1).T + 1.0) * 0.025  # 25 radii apart
    v = rng.normal(0.0, 0.05, x.shape)
    s = Solver(
        box=np.array([[0.0] * 3, [SIDE] * 3]),
        periodic=(False,) * 3,
        gravity=(0, 0, 0),
        skin=SKIN,
        threads=threads,
    )
    s.set_contact_model("hertz", youngs=5e6, poisson=0.45, restitution=0.5, friction=0.4)
    s.add_particles(x, R, densities=2500, velocities=v)
    replica = Replica(x, v)
    fast = []
    # runs of many steps (drifts fused with the particle loop), of one step (a drift of its own
    # each), and speed changes between runs: a sphere 6x, then 300x faster (3 skins per step),
    # all stopped, all moving again
    for steps, change in [
        (700, None),
        (1, None),
        (40, "6x"),
        (3, "300x"),
        (250, "stop"),
        (1, None),
        (500, "again"),
        (1, None),
        (1, None),
        (300, None),
    ]:
        if change == "6x":
            fast = [rng.integers(len(x))]
            v[fast] *= 6.0
        elif change == "300x":
            v[fast] = 300.0 * np.abs(v[fast]).max() * np.sign(v[fast])
        elif change == "stop":
            v[:] = 0.0
        elif change == "again":
            v = rng.normal(0.0, 0.05, x.shape)
        if change:
            s.set_velocities(s.ids, v[s.ids])
            replica.v = v.copy()
        s.run(steps, DT)
        replica.run(steps)
        state = s.get_state()
        by_id = np.argsort(state["core_id"])
        assert s.rebuilds == replica.rebuilds
        assert np.array_equal(state["core_x0"].reshape(-1, 3)[by_id], replica.x0)  # the last one's step
        assert np.array_equal(s.positions, replica.x)
    assert s.lost == 0 and replica.rebuilds > 30
    # all three ways of deciding were taken: a drift that measured, a pass after one that did
    # not, and speeds that ruled a rebuild out
    measured, passes = s.timings["measured_drifts"], s.timings["displacement_passes"]
    assert measured > 0 and passes > 0 and measured + passes < s.step / 2
