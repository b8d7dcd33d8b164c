"""The YADE side of the adapter: a loop that runs inside the Python that imports YADE.

Run as ``python3 worker.py IN_FD OUT_FD`` with YADE's ``py`` directory on ``PYTHONPATH``.
It reads one request at a time from ``IN_FD`` and answers on ``OUT_FD``; each message is
a 4-byte length and a pickle of plain Python values, arrays travelling as ``.npy`` bytes
so that the two sides need not share a numpy version. An answer is ``("ok", value)`` or
``("error", message)``; YADE's own output goes to stdout/stderr, which the adapter sends
to a log file. This module imports only the standard library, numpy and YADE: it never
sees PyGran.
"""

from __future__ import annotations

import io
import math
import os
import pickle
import struct
import sys

import numpy as np

#: Runs up to this many steps call ``O.step()`` in a loop: ``O.run(n, True)`` polls for the
#: end of the run every 40 ms, which dominates short runs.
STEP_LOOP = 64
#: YADE's cell is periodic along every axis: along a non-periodic one it is this many domain
#: lengths long, so that no particle meets an image of itself and a plane wall (3 lengths
#: wide there, see the adapter's ``plane_triangle``) stays under half of it.
APERIODIC_CELL = 10


def sort_axis(periodic) -> int:
    """The collider's sort axis: the first non-periodic one. Its initial sweep along a
    periodic axis misses pairs with a body wider than half the period (a plane wall), which
    never is along a non-periodic axis (see the adapter's ``plane_triangle``)."""
    return next((axis for axis in range(3) if not periodic[axis]), 0)


def to_bytes(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array), allow_pickle=False)
    return buffer.getvalue()


def from_bytes(data: bytes) -> np.ndarray:
    return np.load(io.BytesIO(data), allow_pickle=False)


def vector(values):
    """A YADE ``Vector3`` from three numbers (Boost.Python does not convert numpy scalars)."""
    from yade import Vector3

    return Vector3(*(float(v) for v in values))


def rotation_matrix(q) -> np.ndarray:
    """The rotation matrix of the unit quaternion ``q = (w, x, y, z)``."""
    w, x, y, z = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def set_velocity(state, velocity, omega) -> None:
    """Set a body's velocity and angular velocity; for an aspherical one (a clump) also its
    angular momentum, from which YADE's integrator takes the angular velocity."""
    state.vel, state.angVel = vector(velocity), vector(omega)
    local = state.ori.conjugate() * state.angVel
    state.angMom = state.ori * vector([state.inertia[a] * local[a] for a in range(3)])


def kinetic_energy(state, quantity) -> float:
    """Translational (``ke``) or rotational (``ke_rot``, about the principal axes) energy."""
    if quantity == "ke":
        return 0.5 * state.mass * state.vel.squaredNorm()
    local = state.ori.conjugate() * state.angVel
    return 0.5 * sum(state.inertia[a] * local[a] ** 2 for a in range(3))


def motion_engine(yade, kind, ids, params, now):
    """The YADE engine that moves the bodies ``ids``: ``rotate``, ``translate`` or ``wiggle``
    (starting at time ``now``)."""
    if kind == "rotate":
        return yade.RotationEngine(
            ids=ids,
            rotationAxis=vector(params["axis"]),
            angularVelocity=params["omega"],
            rotateAroundZero=True,
            zeroPoint=vector(params["origin"]),
        )
    if kind == "translate":
        v = np.asarray(params["velocity"], float)
        speed = float(np.linalg.norm(v))
        return yade.TranslationEngine(
            ids=ids, velocity=speed, translationAxis=vector(v / speed if speed else (1, 0, 0))
        )
    # displacement A sin(2 pi (t - t0) / T), starting now: YADE sets the velocity
    # -A w sin(w t + fi) (w = 2 pi f), with fi = -pi/2 - w t0 that is A w cos(w (t - t0)), the
    # derivative of the displacement
    f = 1.0 / params["period"]
    phase = -math.pi / 2 - 2 * math.pi * f * now
    return yade.HarmonicMotionEngine(
        ids=ids, A=vector(params["amplitude"]), f=vector((f, f, f)), fi=vector((phase,) * 3)
    )


def read_message(stream):
    header = stream.read(4)
    if len(header) < 4:
        return None
    (size,) = struct.unpack("<I", header)
    return pickle.loads(stream.read(size))


def write_message(stream, message) -> None:
    data = pickle.dumps(message, protocol=4)
    stream.write(struct.pack("<I", len(data)) + data)
    stream.flush()


class Simulation:
    """One YADE scene built from the adapter's requests (see each method)."""

    def __init__(self) -> None:
        import yade
        from yade import utils

        self.yade = yade
        self.utils = utils
        self.O = yade.Omega()
        self.materials: list[int] = []
        self.species: dict[int, int] = {}  # sphere id -> species
        self.clump_of: dict[int, int] = {}  # clump member id -> clump id
        self.own_mass: dict[int, float] = {}  # clump member id -> the sphere's own mass
        self.bounds: np.ndarray | None = None  # fixed-boundary box; spheres leaving it are deleted
        self.drags: dict[str, dict] = {}  # label -> gamma, species, {radius: engine label}
        # label -> the YADE labels of the engines it added; engines are found by their YADE
        # label, which a scene read back from a checkpoint keeps (Python objects it does not)
        self.engines: dict[str, list[str]] = {}

    # -- setup ----------------------------------------------------------------------------

    def setup(self, model, materials, matches, gravity, box, periodic, dt, verlet):
        """Materials, contact law, gravity and the (periodic) cell; returns material ids.

        ``model`` is ``"hertz"`` or ``"linear"`` (every material then carrying ``betan``);
        ``matches`` maps attributes of the Ip2 functor to ``(material i, material j, value)``;
        ``verlet`` the collider's ``verletDist`` (m; each bound's margin, so pairs within twice
        it are found ahead), ``None`` for YADE's default.
        """
        y, O = self.yade, self.O  # noqa: E741 - YADE's own name for the scene
        O.reset()
        for props in materials:
            cls = y.FrictViscoMat if model == "linear" else y.FrictMat
            O.materials.append(cls(**props))
        self.materials = [m.id for m in O.materials]
        makers = {
            name: y.MatchMaker(
                matches=[(self.materials[i], self.materials[j], value) for i, j, value in pairs]
            )
            for name, pairs in matches.items()
        }
        if model == "hertz":
            ip2 = y.Ip2_FrictMat_FrictMat_MindlinPhys(**makers)
            law2 = y.Law2_ScGeom_MindlinPhys_Mindlin()
        else:
            ip2 = y.Ip2_FrictViscoMat_FrictViscoMat_FrictViscoPhys(kRatio=1.0, **makers)
            law2 = y.Law2_ScGeom_FrictViscoPhys_CundallStrackVisco()
        box = np.asarray(box, float)
        if any(periodic):
            lengths = box[:, 1] - box[:, 0]
            O.periodic = True
            O.cell.setBox(tuple(lengths[i] if periodic[i] else APERIODIC_CELL * lengths[i] for i in range(3)))
        self.periodic = tuple(bool(p) for p in periodic)
        self.bounds = box
        O.engines = [
            y.ForceResetter(),
            # plane walls are facets wider than the period: they meet spheres at their unwrapped positions
            y.InsertionSortCollider(
                [y.Bo1_Sphere_Aabb(), y.Bo1_Facet_Aabb()],
                allowBiggerThanPeriod=True,
                sortAxis=sort_axis(periodic),
                **({} if verlet is None else {"verletDist": verlet}),
            ),
            # hertzian: a facet's reference radius is 1e8 sphere radii, so R* = R as for a flat wall
            y.InteractionLoop(
                [y.Ig2_Sphere_Sphere_ScGeom(), y.Ig2_Facet_Sphere_ScGeom(hertzian=True)], [ip2], [law2]
            ),
            y.NewtonIntegrator(damping=0.0, gravity=vector(gravity)),
        ]
        O.dt = dt
        return self.materials

    # -- bodies ---------------------------------------------------------------------------

    def spheres(self, centres, radii, velocities, omegas, material, species):
        """Add spheres of one material and species; returns their ids."""
        centres, radii = from_bytes(centres), from_bytes(radii)
        velocities, omegas = from_bytes(velocities), from_bytes(omegas)
        bodies = [
            self.utils.sphere(vector(c), float(r), material=self.materials[material])
            for c, r in zip(centres, radii)
        ]
        for body, v, w in zip(bodies, velocities, omegas):
            body.state.vel, body.state.angVel = vector(v), vector(w)
        ids = self.O.bodies.append(bodies)
        for i in ids:
            self.species[i] = species
        for label in self.drags:
            self._drag(label, ids)
        return ids

    def assign(self, ids, velocity, omega, radius):
        """Give the spheres ``ids`` (YADE body ids) a velocity, angular velocity and/or radius
        (``None``: unchanged); a new radius resizes the mass and inertia at the material's density."""
        for i in from_bytes(ids).tolist():
            body = self.O.bodies[i]
            if velocity is not None:
                body.state.vel = vector(velocity)
            if omega is not None:
                body.state.angVel = vector(omega)
            if radius is not None:
                body.shape.radius = float(radius)
                body.state.mass = body.material.density * 4 / 3 * math.pi * radius**3
                body.state.inertia = vector([0.4 * body.state.mass * radius**2] * 3)
        return None

    def clumps(self, centres, orientations, template, velocities, omegas, material, species, discretization):
        """Add rigid clumps of the ``template`` spheres ``(k, 4)``: offsets ``(x, y, z)`` in the
        particle's frame and radii, the frame's origin at each of ``centres`` and rotated by
        each of ``orientations`` (unit quaternions ``w, x, y, z``). YADE computes each clump's
        mass, centre and principal inertia, on a grid of ``discretization`` cells across the
        clump's thinnest extent where members overlap (the union's volume, overlap counted
        once). Each member's mass becomes the clump's, so that contact damping uses the body's
        mass as LIGGGHTS does; returns the clump ids."""
        centres, orientations, template = from_bytes(centres), from_bytes(orientations), from_bytes(template)
        velocities, omegas = from_bytes(velocities), from_bytes(omegas)
        made = []
        for centre, q, v, w in zip(centres, orientations, velocities, omegas):
            offsets = template[:, :3] @ rotation_matrix(q).T
            members = [
                self.utils.sphere(vector(centre + d), float(r), material=self.materials[material])
                for d, r in zip(offsets, template[:, 3])
            ]
            clump, ids = self.O.bodies.appendClumped(members, discretization=int(discretization))
            state = self.O.bodies[clump].state
            set_velocity(state, v, w)
            for i in ids:
                member = self.O.bodies[i].state
                self.own_mass[i] = member.mass
                member.mass = state.mass
                self.species[i] = species
                self.clump_of[i] = clump
            made.append(clump)
        return made

    def clump_properties(self):
        """Every clump's id, mass, centre and inertia tensor about its centre in the world frame."""
        clumps = sorted(set(self.clump_of.values()))
        mass, centre, inertia = [], [], []
        for i in clumps:
            state = self.O.bodies[i].state
            turn = rotation_matrix([state.ori[3], state.ori[0], state.ori[1], state.ori[2]])
            mass.append(state.mass)
            centre.append([state.pos[a] for a in range(3)])
            inertia.append(turn @ np.diag([state.inertia[a] for a in range(3)]) @ turn.T)
        return {
            "id": to_bytes(np.array(clumps, np.int64)),
            "mass": to_bytes(np.array(mass, float)),
            "centre": to_bytes(np.array(centre, float).reshape(-1, 3)),
            "inertia": to_bytes(np.array(inertia, float).reshape(-1, 3, 3)),
        }

    def facets(self, triangles, material):
        """Add fixed facets, one per triangle ``(T, 3, 3)``; returns their ids."""
        triangles = from_bytes(triangles)
        bodies = [
            self.utils.facet([vector(p) for p in tri], material=self.materials[material], wire=False)
            for tri in triangles
        ]
        return self.O.bodies.append(bodies)

    def facet_vertices(self, ids):
        """Current corners ``(T, 3, 3)`` of the facets ``ids`` (moving meshes move them)."""
        out = np.empty((len(ids), 3, 3))
        for k, i in enumerate(ids):
            body = self.O.bodies[i]
            out[k] = [body.state.pos + body.state.ori * v for v in body.shape.vertices]
        return to_bytes(out)

    def erase(self, ids):
        """Erase bodies; a clump member takes its whole clump with it."""
        for i in ids:
            clump = self.clump_of.get(i)
            if clump is not None:
                for member in [m for m, c in self.clump_of.items() if c == clump]:
                    del self.clump_of[member], self.own_mass[member]
                    self.species.pop(member, None)
                self.O.bodies.erase(clump, True)
                continue
            if self.O.bodies[i] is not None:
                self.O.bodies.erase(i)
            self.species.pop(i, None)

    # -- engines --------------------------------------------------------------------------

    def motion(self, label, kind, ids, params):
        """Rigid motion of the facets ``ids`` (see :func:`motion_engine`)."""
        self._insert_engine(label, motion_engine(self.yade, kind, ids, params, self.O.time))

    def drag_force(self, label, gamma, species):
        """Viscous force ``-gamma v`` on the spheres of ``species``, now and later inserted:
        YADE's ``LinearDragEngine`` (``b = 6 pi nu r``), one engine per particle radius."""
        self.drags[label] = {"gamma": gamma, "species": set(species), "engines": {}}
        self.engines[label] = []
        self._drag(label, list(self.species))

    def _drag(self, label, ids):
        """Put the spheres ``ids`` of the drag's species under its engine of their radius."""
        drag = self.drags[label]
        by_radius: dict[float, list[int]] = {}
        for i in ids:
            if self.species[i] in drag["species"]:
                by_radius.setdefault(self.O.bodies[i].shape.radius, []).append(i)
        for radius, chosen in by_radius.items():
            name = drag["engines"].get(radius)
            if name is None:
                engine = self.yade.LinearDragEngine(nu=drag["gamma"] / (6 * math.pi * radius))
                drag["engines"][radius] = self._insert_engine(label, engine)
            else:
                engine = self._engine(name)
            engine.ids = list(engine.ids) + chosen

    def _insert_engine(self, label, engine) -> str:
        """Put ``engine`` just before the integrator, file it under ``label``; returns the YADE
        label it is given."""
        names = self.engines.setdefault(label, [])
        engine.label = f"pygran_{label}_{len(names)}"
        names.append(engine.label)
        listed = list(self.O.engines)
        self.O.engines = listed[:-1] + [engine, listed[-1]]
        return engine.label

    def _engine(self, name):
        return next(e for e in self.O.engines if e.label == name)

    def remove_engine(self, label):
        names = set(self.engines.pop(label))
        self.drags.pop(label, None)
        self.O.engines = [e for e in self.O.engines if e.label not in names]

    # -- checkpoints ----------------------------------------------------------------------

    def save(self):
        """The scene as YADE serializes it (bodies, interactions with their histories, engines,
        clock; ``O.sceneToString``) and this side's bookkeeping in plain values, for a checkpoint."""
        book = {
            "species": sorted(self.species.items()),
            "clump_of": sorted(self.clump_of.items()),
            "own_mass": sorted(self.own_mass.items()),
            "drags": {
                label: dict(drag, species=sorted(drag["species"]), engines=[*drag["engines"].items()])
                for label, drag in self.drags.items()
            },
            "engines": self.engines,
        }
        return {"scene": self.O.sceneToString(), "book": book}

    def load(self, scene, book):
        """Replace the scene by a :meth:`save` result. Its interactions continue as they were;
        the collider lists the pairs not yet touching again, so the order forces are summed in
        changes: a resumed run differs from an uninterrupted one in the last digits."""
        self.O.stringToScene(scene)
        self.species = {int(i): int(s) for i, s in book["species"]}
        self.clump_of = {int(i): int(c) for i, c in book["clump_of"]}
        self.own_mass = {int(i): float(m) for i, m in book["own_mass"]}
        self.drags = {
            label: {"gamma": d["gamma"], "species": set(d["species"]), "engines": dict(d["engines"])}
            for label, d in book["drags"].items()
        }
        self.engines = book["engines"]

    # -- running and results ----------------------------------------------------------

    @property
    def box(self) -> np.ndarray:
        """The fixed-boundary box ``(3, 2)`` that :meth:`setup` set."""
        if self.bounds is None:
            raise RuntimeError("the scene has no domain: call setup first")
        return self.bounds

    def run(self, nsteps, dt):
        """Advance ``nsteps`` steps of ``dt``, then delete the spheres that left a fixed
        boundary or whose position or velocity is no longer finite (LIGGGHTS deletes them
        too); returns what was deleted (see :meth:`_drop_lost`)."""
        self.O.dt = dt
        if nsteps <= STEP_LOOP:
            for _ in range(nsteps):
                self.O.step()
        else:
            self.O.run(int(nsteps), True)
        return self._drop_lost()

    def _drop_lost(self):
        """Delete lost spheres; returns ``{"count", "where", "max_speed"}``: how many, how many
        by place (a face such as ``"z-"``, below the lower z bound, or ``"non-finite"``) and
        the largest speed of those that left through a face (``None`` if none did). A lost
        clump member takes its whole clump, counted at the same place."""
        fixed = [axis for axis in range(3) if not self.periodic[axis]]
        box = self.box
        gone: list[int] = []
        where: dict[str, int] = {}
        speeds: list[float] = []
        taken: set[int] = set()
        for i in self.species:
            if i in taken:
                continue  # already going with its clump
            state = self.O.bodies[i].state
            pos, vel = [state.pos[a] for a in range(3)], [state.vel[a] for a in range(3)]
            if not all(math.isfinite(c) for c in pos + vel):
                place = "non-finite"
            else:
                low = [a for a in fixed if pos[a] < box[a, 0]]
                high = [a for a in fixed if pos[a] > box[a, 1]]
                if not low and not high:
                    continue
                place = "xyz"[low[0]] + "-" if low else "xyz"[high[0]] + "+"
                speeds.append(math.sqrt(sum(c * c for c in vel)))
            gone.append(i)
            where[place] = where.get(place, 0) + 1
            if i in self.clump_of:
                clump = self.clump_of[i]
                others = [m for m, c in self.clump_of.items() if c == clump and m != i]
                gone.extend(others)
                taken.update(others)
                where[place] += len(others)
        self.erase(gone)
        return {"count": len(gone), "where": where, "max_speed": max(speeds) if speeds else None}

    def extract(self, quantity):
        """Per-sphere ``quantity`` ordered by id (forces include gravity, as in LIGGGHTS)."""
        ids = sorted(self.species)
        bodies = [self.O.bodies[i] for i in ids]
        rows: list
        if quantity == "x":
            rows = [b.state.pos for b in bodies]
        elif quantity == "v":
            rows = [b.state.vel for b in bodies]
        elif quantity == "omega":
            rows = [b.state.angVel for b in bodies]
        elif quantity == "f":  # a clump member's gravity is that of its own sphere
            g = np.asarray(self.O.engines[-1].gravity)
            rows = [
                np.asarray(self.O.forces.f(i)) + self.own_mass.get(i, b.state.mass) * g
                for i, b in zip(ids, bodies)
            ]
        elif quantity == "torque":
            rows = [self.O.forces.t(i) for i in ids]
        elif quantity == "radius":
            rows = [b.shape.radius for b in bodies]
        elif quantity == "mass":
            rows = [b.state.mass for b in bodies]
        elif quantity == "id":
            rows = [i + 1 for i in ids]
        elif quantity == "type":
            rows = [self.species[i] for i in ids]
        elif quantity == "body":
            rows = [self.clump_of.get(i, -2) + 1 for i in ids]
        else:
            raise ValueError(f"unknown quantity {quantity!r}")
        if quantity in ("id", "type", "body"):
            return to_bytes(np.array(rows, np.int64))
        if quantity in ("radius", "mass"):
            return to_bytes(np.array(rows, float))
        values = np.array(rows, float).reshape(-1, 3)
        if quantity == "x" and self.O.periodic:
            box, wrap = self.box, np.array(self.periodic)
            lo, length = box[:, 0], box[:, 1] - box[:, 0]
            values[:, wrap] = lo[wrap] + np.mod(values[:, wrap] - lo[wrap], length[wrap])
        return to_bytes(values)

    def scalar(self, quantity):
        """``contacts`` (real interactions), ``ke`` or ``ke_rot`` (of the spheres and clumps,
        each clump once) or ``pwave_dt`` (``utils.PWaveTimeStep``)."""
        if quantity == "contacts":
            return sum(1 for i in self.O.interactions if i.isReal)
        if quantity in ("ke", "ke_rot"):
            moving = [i for i in self.species if i not in self.clump_of] + sorted(set(self.clump_of.values()))
            return sum(kinetic_energy(self.O.bodies[i].state, quantity) for i in moving)
        if quantity == "pwave_dt":
            return self.utils.PWaveTimeStep()
        raise ValueError(f"unknown scalar {quantity!r}")

    def command(self, text):
        """Execute YADE Python ``text`` with ``from yade import *`` in scope."""
        scope = {"__name__": "__yade_command__"}
        exec("from yade import *\nfrom yade import utils, ymport, pack\n", scope)
        exec(text, scope)


def main() -> None:
    requests = os.fdopen(int(sys.argv[1]), "rb")
    answers = os.fdopen(int(sys.argv[2]), "wb")
    try:
        simulation = Simulation()
    except BaseException as exc:  # noqa: BLE001 - reported to the adapter, then exit
        write_message(answers, ("error", f"cannot start YADE: {type(exc).__name__}: {exc}"))
        return
    write_message(answers, ("ok", simulation.yade.config.revision))
    while True:
        message = read_message(requests)
        if message is None or message[0] == "close":
            return
        method, kwargs = message
        try:
            result = getattr(simulation, method)(**kwargs)
            write_message(answers, ("ok", result))
        except Exception as exc:  # noqa: BLE001 - every YADE error goes back to the adapter
            write_message(answers, ("error", f"{type(exc).__name__}: {exc}"))


if __name__ == "__main__":
    main()
