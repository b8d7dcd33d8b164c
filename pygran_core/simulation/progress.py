"""Progress lines of a simulation's runs, for output that is not a terminal (a file, a batch
job's log): every ``every`` seconds of a run, the step, the simulated time, the speed in
particle-steps per second and the time left, of the run and, when the script declared its
total steps (``progress={'steps': ...}``), of the whole script.

A line reads::

    progress: step 4000, run 3000 of 10000 (30 %), t = 0.04 s, 1.2e+06 particle-steps/s,
    run ETA 0:00:07; script 7000 of 20000 steps (35 %), ETA 0:00:13

(on one line). :class:`Progress` only composes and times them; the engine writes them to its
log file and, off a terminal, to stderr.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from pygran_core.simulation.specs import ProgressSpec


def duration(seconds: float) -> str:
    """``h:mm:ss`` (``?`` when not finite)."""
    if not math.isfinite(seconds):
        return "?"
    whole = int(round(max(seconds, 0.0)))
    return f"{whole // 3600}:{whole // 60 % 60:02d}:{whole % 60:02d}"


class Progress:
    """The progress of one simulation's runs: :meth:`begin` at the start of a run,
    :meth:`update` after each of its pieces (a line through ``write`` when ``every`` seconds
    have passed since the last), :meth:`end` at its end. Steps accumulate over the runs, for
    the script's ETA. ``collective``: count the particles at every update, not only for a line
    (under MPI counting is collective, and each rank's clock decides differently)."""

    def __init__(
        self,
        spec: ProgressSpec,
        write: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
        collective: bool = False,
    ) -> None:
        self.spec, self._write, self._clock, self._collective = spec, write, clock, collective
        self.done = 0  #: steps of the script so far, over all its runs (a resumed script's too)
        # the run's first and end step, the step and clock this process began it at, and the
        # script's steps before the run
        self._run = (0, 0, 0, 0.0, 0)
        self._last = 0.0
        self.lines = 0  #: lines written in the current run

    def skip(self, steps: int) -> None:
        """Count a run a resumed script had finished before its checkpoint."""
        self.done += steps

    def begin(self, step: int, end: int, first: int | None = None) -> None:
        """Start timing a run that ends at ``end``, from ``step``; ``first``: the run's first
        step when ``step`` is later (the run resumed from a checkpoint taken in it)."""
        now = self._clock()
        first = step if first is None else first
        self._run, self._last, self.lines = (first, end, step, now, self.done), now, 0
        self.done += step - first

    def update(self, step: int, simulated: float, particles: Callable[[], int]) -> None:
        """Count the steps up to ``step``; write a line if one is due (``particles`` is called
        then only, unless ``collective``: counting may gather them from the solver)."""
        first, _, _, _, before = self._run
        self.done = before + step - first
        count = particles() if self._collective else None
        now = self._clock()
        if now - self._last >= self.spec.every:
            self._last = now
            self.lines += 1
            self._write(self.line(step, simulated, particles() if count is None else count, now))

    def end(self, step: int) -> str:
        """The run's summary: steps, wall time and speed."""
        _, _, began, started, _ = self._run
        elapsed = self._clock() - started
        rate = (step - began) / elapsed if elapsed > 0 else math.inf
        return f"run of {step - began} steps took {duration(elapsed)} ({rate:.3g} steps/s)"

    def line(self, step: int, simulated: float, particles: int, now: float) -> str:
        first, end, began, started, _ = self._run
        ran, total = step - first, end - first
        rate = (step - began) / (now - started) if now > started and step > began else math.nan
        parts = [
            f"progress: step {step}, run {ran} of {total} ({100 * ran / total:.0f} %), t = {simulated:.6g} s",
            f"{particles * rate:.3g} particle-steps/s",
            f"run ETA {duration((end - step) / rate)}",
        ]
        text = ", ".join(parts)
        planned = self.spec.steps
        if planned is not None:
            if self.done <= planned:
                text += (
                    f"; script {self.done} of {planned} steps ({100 * self.done / planned:.0f} %), "
                    f"ETA {duration((planned - self.done) / rate)}"
                )
            else:
                text += f"; script {self.done} steps, past the {planned} declared (progress={{'steps': ...}})"
        return text
