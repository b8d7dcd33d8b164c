"""The insertions LIGGGHTS makes itself (``fix insert/pack``, ``fix insert/rate/region``): the
steps of their events, what the by-pack ones ask for as LIGGGHTS counts it, and what each
event made, read from LIGGGHTS' screen file and reported as the placing engines report it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pygran_core.errors import PyGranWarning
from pygran_core.simulation import clumps
from pygran_core.simulation.diagnostics import LostParticles, exit_faces
from pygran_core.simulation.engine import Engine
from pygran_core.simulation.insertion import report_shortfall
from pygran_liggghts.channel import Channel
from pygran_liggghts.commands import Commands, size_classes
from pygran_liggghts.screen import InsertionEvent, insertion_events

if TYPE_CHECKING:
    from pygran_core.simulation.calls import InsertSpec


class FixInsertions:
    """The insertion fixes of one simulation on LIGGGHTS, by label. ``engine`` logs and warns
    and tells the step; ``channel`` gathers LIGGGHTS' arrays (collectively: every rank takes
    part); ``screen`` is LIGGGHTS' screen file, read on rank 0 (``None`` on the others)."""

    def __init__(self, engine: Engine, channel: Channel, commands: Commands, screen: Path | None) -> None:
        self._engine = engine
        self._channel = channel
        self._commands = commands
        self._screen = screen
        self.specs: dict[str, InsertSpec] = {}  # label -> the request LIGGGHTS was given
        #: label -> (first step, steps between, last step or None) of each insertion's events
        self._steps: dict[str, tuple[int, int, int | None]] = {}
        #: By-pack insertions LIGGGHTS has not made yet (it makes them as the next run starts)
        self._unplaced: dict[str, InsertSpec] = {}
        #: Reading the events from the screen file: how far it has been read, the particles
        #: asked for at the first step of the run by the by-pack insertions made then (and
        #: whether exactly), those by rate asked for per event, the insertions whose shortfall
        #: was warned about, and the volume fractions inserted in the run, whose outcome is logged
        self._screen_read = 0
        self._asked: dict[str, tuple[int, bool] | None] = {}
        self._per_event: dict[str, float] = {}
        self._short_warned: set[str] = set()
        self._filling: list[str] = []

    def add(self, label: str, spec: InsertSpec) -> None:
        """Insertion ``label`` of ``spec`` was just given to LIGGGHTS."""
        engine = self._engine
        self.specs[label] = spec
        # LIGGGHTS' events: from the next step on, every insert_every steps; by rate, until
        # about its duration is over (its last event may come up to one interval later)
        every = self._commands.insert_every(spec, engine.dt)
        first = engine.step + 1
        if every is None:
            self._steps[label] = (first, 1, first)
        else:
            duration = None if spec.mechanism == "by_pack" else spec.duration
            last = (
                None if duration is None or engine.dt is None else first + round(duration / engine.dt) + every
            )
            self._steps[label] = (first, every, last)
        if spec.mechanism == "by_pack" and not engine.replaying:
            self._unplaced[label] = spec

    def remove(self, label: str) -> None:
        for kept in (self.specs, self._steps, self._unplaced):
            kept.pop(label, None)

    def stops(self, start: int, end: int) -> set[int]:
        """The insertion events' steps strictly between ``start`` and ``end``."""
        stops: set[int] = set()
        for first, every, last in self._steps.values():
            skip = max(0, -(-(start + 1 - first) // every))  # events before start + 1
            stops.update(range(first + skip * every, min(end, last + 1 if last is not None else end), every))
        return stops

    def target(self, spec: InsertSpec) -> InsertSpec:
        """By-pack insertion ``spec`` with the target LIGGGHTS is given: for a number of
        particles, those asked for on top of the ones it counts in the region when it inserts
        (:meth:`particles_in`) and of those that earlier by-pack insertions into the same
        region will place as the next run starts (LIGGGHTS inserts then; the placing engines
        at the call, whose counts the front end adds)."""
        if spec.target != "particles_in_region":
            return spec
        engine = self._engine
        requested = spec.requested or 0
        present = self.particles_in(spec.region, engine.dt)
        if self._commands.body_types or requested + present != spec.value:
            engine.log(
                "insert: %g particles on top of the %d in the region as LIGGGHTS counts them when it "
                "inserts, at step %d: a single sphere when its centre is in it, a multisphere particle "
                "once when the centre of its bounding sphere is (sphere centres in it now: %d)",
                requested,
                present,
                engine.step + 1,
                spec.value - requested,
            )
        spec = replace(spec, value=requested + present)
        earlier = [other for other in self._unplaced.values() if other.region == spec.region]
        waiting = sum(int(other.requested or 0) for other in earlier if other.target == spec.target)
        uncounted = sorted({other.target for other in earlier if other.target != spec.target})
        if uncounted:
            engine.messages.warn(
                f"insert: the particles an earlier insert() of {' and '.join(uncounted)} into this "
                "region makes as the next run starts cannot be counted now; LIGGGHTS counts them "
                "against this insertion's target, which may then place fewer than asked: run at least "
                "one step between the two insert() calls",
                PyGranWarning,
            )
        if waiting:
            engine.log(
                "insert: %d particles of earlier insert() calls into this region, made as the next run "
                "starts, counted as present",
                waiting,
            )
        return replace(spec, value=spec.value + waiting)

    def starting(self, dt: float) -> None:
        """Before a run of steps ``dt``: count what the by-pack insertions LIGGGHTS makes as
        it starts ask for, and note the volume fractions inserted in it."""
        self._asked = {label: self._asked_by(spec, dt) for label, spec in self._unplaced.items()}
        self._filling = [
            label
            for label, spec in self.specs.items()
            if spec.target == "volumefraction_region" and (label in self._unplaced or spec.freq)
        ]
        self._unplaced.clear()

    def report(self, start: int, end: int) -> None:
        """After the run from step ``start`` to ``end``: log its insertion events (see
        :meth:`_report_events`) and the volume fractions its insertions reached."""
        self._report_events(start)
        if self._filling:
            self._log_fractions(self._filling, end)

    def lost(
        self, losses: list[tuple[int, np.ndarray, np.ndarray]], pieces: list[int], dt: float
    ) -> LostParticles:
        """The particles lost in the pieces of a run between insertion events (:meth:`stops`),
        ``pieces`` steps of ``dt`` long: in each, how many, and the positions and velocities at
        its start of those present then, placed as the front end places them; the others,
        inserted and lost within it, ``unknown``."""
        where: dict[str, int] = {}
        for (count, x, v), steps in zip(losses, pieces):
            for place in [*exit_faces(self._engine.spec, x, v, steps * dt), *["unknown"] * (count - len(x))]:
                where[place] = where.get(place, 0) + 1
        total = sum(where.values())
        self._engine.log(
            "%d particle%s lost in the last %d steps: %s",
            total,
            "" if total == 1 else "s",
            sum(pieces),
            where,
        )
        return LostParticles(total, where)

    def particles_in(self, region: Any, dt: float | None) -> int:
        """The particles LIGGGHTS counts in ``region`` as it inserts, at the step after this one
        (of ``dt``; ``None``: no step to move by): as LIGGGHTS 3.8's ``fix insert/pack``
        counts them (``FixInsertPack::calc_ninsert_this``), a single sphere when its centre is
        in it (also with ``all_in``) and a multisphere particle once, when the centre of its
        bounding sphere is (:func:`~pygran_core.simulation.clumps.bounding_centres`). LIGGGHTS
        counts after the step's first half has moved the particles, so they are moved here as
        its integrators move them: a single sphere by ``dt (v + dt f / 2m)`` (``fix
        nve/sphere``: exactly), the spheres of a clump by ``dt v`` (``fix multisphere``, within
        ``dt^2`` times the clump's accelerations). Counted without moving them, a particle
        crossing a face of the region in that step would be miscounted, and the insertion
        would make one particle more or fewer than asked."""
        bodies = bool(self._commands.body_types)
        names = ["x", "v", "f", "mass", *(["mol", "type"] if bodies else [])]
        arrays = self._channel.gather(*names)
        x, v, f = (arrays[name].reshape(-1, 3) for name in ("x", "v", "f"))
        single = arrays["mol"] < 0 if bodies else np.ones(len(x), bool)
        if dt is not None:
            half = v + np.where(single, 0.5 * dt / arrays["mass"], 0.0)[:, None] * f
            x = x + dt * half
        points = x[single]
        if bodies:
            species = self._engine.spec.species
            templates = {k: species[k - 1].spheres for k in self._commands.body_types}
            _, centres = clumps.bounding_centres(x, arrays["mol"], arrays["type"], templates)
            points = np.vstack([points, centres])
        return int(np.count_nonzero(region.contains(points)))

    def _asked_by(self, spec: InsertSpec, dt: float) -> tuple[int, bool] | None:
        """The particles by-pack insertion ``spec`` asks for as the next run (of steps ``dt``)
        starts, as LIGGGHTS counts them: its target less what its region holds, exactly for a
        number of particles (:meth:`particles_in`); for a volume or mass, what lacks over the
        expected volume or mass of one particle, to which LIGGGHTS adds a uniform draw before
        rounding down (about); ``None`` for the volume or mass of multisphere bodies, which
        LIGGGHTS computes."""
        if spec.target == "particles_in_region":
            return int(spec.value) - self.particles_in(spec.region, dt), True
        if self._commands.body_types:
            return None
        arrays = self._channel.gather("x", "radius", "mass")
        inside = spec.region.contains(arrays["x"].reshape(-1, 3))
        species = self._engine.spec.species
        sizes = [
            (weight * fraction, 4 / 3 * math.pi * radius**3, species[index - 1].density)
            for index, weight in zip(spec.species, spec.weights)
            for radius, fraction in size_classes(species[index - 1].radius)
        ]
        total = sum(share for share, _, _ in sizes)
        if spec.target == "volumefraction_region":
            lacking = spec.value * spec.region.volume() - float(
                np.sum(4 / 3 * np.pi * arrays["radius"][inside] ** 3)
            )
            one = sum(share * volume for share, volume, _ in sizes) / total
        else:
            lacking = spec.value - float(np.sum(arrays["mass"][inside]))
            one = sum(share * volume * density for share, volume, density in sizes) / total
        return max(0, round(lacking / one)), False

    def _report_events(self, start: int) -> None:
        """Log the insertion events of the run that began at step ``start`` from LIGGGHTS'
        screen file; one that inserted fewer than it asked for (its region full) is an
        :class:`InsertionWarning`, the first time for each insertion, then logged."""
        if self._screen is None:
            return
        try:
            with self._screen.open("rb") as screen:
                screen.seek(self._screen_read)
                text = screen.read()
        except FileNotFoundError:
            return
        text = text[: text.rfind(b"\n") + 1]  # whole lines only
        self._screen_read += len(text)
        events, per_event = insertion_events(text.decode(errors="replace"))
        self._per_event.update(per_event)
        first: list[tuple[InsertSpec, int]] = []  # insertions made as the run started, in order
        for event in events:
            spec = self.specs.get(event.fix)
            if spec is None:
                continue
            asked = self._asked.pop(event.fix, None) if event.step == start + 1 else None
            if asked is not None:
                asked = self._after_earlier(spec, asked, first)
                first.append((spec, event.inserted))
            if not event.short:
                if asked is not None and asked[1]:  # as the placing engines log it
                    self._engine.log(
                        "insert at step %d: %d of %d particles", event.step, event.inserted, asked[0]
                    )
                else:
                    self._engine.log("insert at step %d: %d particles", event.step, event.inserted)
                continue
            report_shortfall(
                self._engine.messages, self._shortfall(event, spec, asked), event.fix in self._short_warned
            )
            self._short_warned.add(event.fix)
        self._asked.clear()

    @staticmethod
    def _after_earlier(
        spec: InsertSpec, asked: tuple[int, bool], earlier: list[tuple[InsertSpec, int]]
    ) -> tuple[int, bool]:
        """What by-pack insertion ``spec`` asked for as the run started (``asked`` counted
        before it), after the ``earlier`` insertions of that step (spec, particles made):
        LIGGGHTS makes them one after the other, each counting what the ones before placed in
        its region (exactly for the same region; about when another region overlaps it)."""
        number, exact = asked
        for other, made in earlier:
            if other.region == spec.region:
                number -= made  # for a volume or mass, as many expected particles: about anyway
            else:
                mine, theirs = spec.region.bounds(), other.region.bounds()
                if np.all((mine[:, 0] < theirs[:, 1]) & (theirs[:, 0] < mine[:, 1])):
                    exact = False
        return max(number, 0), exact

    def _log_fractions(self, labels: list[str], step: int) -> None:
        """Log the volume fraction the regions of by-pack insertions ``labels`` hold at ``step``
        (collective: every rank gathers)."""
        arrays = self._channel.gather("x", "radius")
        for label in labels:
            spec = self.specs[label]
            inside = spec.region.contains(arrays["x"].reshape(-1, 3))
            held = float(np.sum(4 / 3 * np.pi * arrays["radius"][inside] ** 3)) / spec.region.volume()
            self._engine.log(
                "volume fraction in the region %s at step %d: %.3g of the %.3g asked for",
                spec.region,
                step,
                held,
                spec.value,
            )

    def _shortfall(self, event: InsertionEvent, spec: InsertSpec, asked: tuple[int, bool] | None) -> str:
        """What LIGGGHTS' insertion ``event`` (of ``spec``) asked for and inserted, as the
        placing engines say it. ``asked``: what a by-pack insertion asked for as the run
        started (see :meth:`_asked_by`); a batch by rate asks for ``int(per + uniform)`` (exact
        for a whole number); otherwise (a repeated by-pack insertion) its target is named."""
        made = event.inserted
        where = f"the region {spec.region} is full"
        per = self._per_event.get(event.fix) if spec.mechanism == "by_rate" else None
        if asked is None and per is not None:
            asked = round(per), per.is_integer()
        if asked is not None and asked[0] > made:
            number, exact = asked
            about = "" if exact else "about "
            return (
                f"insertion at step {event.step}: {made} of {about}{number} particles inserted, {where} "
                f"(no free place for the other {about}{number - made})"
            )
        amount = f"{spec.value:g}" if spec.target == "particles_in_region" else f"{spec.value:.3g}"
        return (
            f"insertion at step {event.step}: {made} particles inserted, fewer than its target "
            f"({spec.target} {amount}) needs, {where}"
        )
