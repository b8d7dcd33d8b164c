"""User mistakes, one per row, for the engine conformance suite (and any engine's tests):
each gives the same :class:`~pygran_core.errors.PyGranError` subclass on every engine, and a
message that names the key (or value) at fault.

``SETUP`` rows are mistakes in ``simulation.DEM(**params)``: the params start from
:func:`valid` (two species of ``params.organic``, gravity, ``dt``) and the row changes it.
``CALL`` rows are mistakes in a call on a running simulation (see :func:`running`): every
mistake is refused before it changes anything. ``UNSUPPORTED`` rows are settings only some
engines honour: refused, naming the capability, by the others.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pygran_core import params
from pygran_core.errors import ConfigError, PluginNotFound, UnsupportedFeature
from pygran_core.simulation.dem import DEM
from pygran_core.simulation.engine import Handle
from pygran_core.simulation.models import ContactModel, HertzMindlin

R = 1e-3
BOX = (0.0, 0.02, 0.0, 0.02, 0.0, 0.02)
#: A 2 mm square (two triangles) in the plane z = 3, in millimetres, as the original examples' meshes.
SQUARE = """solid square
facet normal 0 0 1
 outer loop
  vertex -1 -1 3
  vertex 1 -1 3
  vertex 1 1 3
 endloop
endfacet
facet normal 0 0 1
 outer loop
  vertex -1 -1 3
  vertex 1 1 3
  vertex -1 1 3
 endloop
endfacet
endsolid square
"""


def square_stl(p: dict[str, Any]) -> Path:
    """:data:`SQUARE` written beside the output folder of the params ``p``."""
    path = Path(p["output"]).parent / "square.stl"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(SQUARE)
    return path


def valid(output: Path, engine: str, model: type[ContactModel] = HertzMindlin) -> dict[str, Any]:
    """A valid simulation of two species of ``params.organic`` writing to ``output``; the rows
    change it."""
    material = dict(params.organic)
    return {
        "engine": engine,
        "model": model,
        "box": BOX,
        "species": ({"material": material, "radius": R}, {"material": dict(material), "radius": R / 2}),
        "gravity": (9.81, 0, 0, -1),
        "dt": 5e-6,
        "output": str(output),
        "traj": {"pfile": None},
        "progress": False,
    }


def _species(change):
    """A SETUP row's change to the first species (``change(species) -> species``)."""

    def apply(p):
        first, second = p["species"]
        return {**p, "species": (change(dict(first)), second)}

    return apply


def _material(**values):
    return _species(lambda s: {**s, "material": {**s["material"], **values}})


def _traj(**values):
    return lambda p: {**p, "traj": {**p["traj"], **values}}


def _mesh(**entry):
    return lambda p: {**p, "mesh": {"plate": {"file": str(square_stl(p)), **entry}}}


def _set(**values):
    return lambda p: {**p, **values}


def _output_in(place: str):
    """A SETUP row's output folder where a file ``a-file`` beside the valid one stands:
    ``place`` ``'at'`` the file itself, ``'under'`` a folder inside it."""

    def apply(p):
        blocker = Path(p["output"]).parent / "a-file"
        blocker.parent.mkdir(parents=True, exist_ok=True)
        blocker.touch()
        return {**p, "output": str(blocker if place == "at" else blocker / "out")}

    return apply


#: (id, change to the valid params, error class, what the message must name)
SETUP = [
    ("unknown keyword", _set(gravty=(9.81, 0, 0, -1)), ConfigError, "'gravity'"),
    ("box of five numbers", _set(box=(0, 1, 0, 1, 0)), ConfigError, "box"),
    ("box upside down", _set(box=(0, 1, 0, 1, 1, 0)), ConfigError, "box"),
    ("boundary flag", _set(boundary=("p", "x", "f")), ConfigError, "boundary"),
    ("boundary as one string", _set(boundary="ppf"), ConfigError, "boundary"),
    ("periodic on one face only", _set(boundary=("pf", "f", "f")), ConfigError, "boundary x"),
    ("gravity without a unit vector", _set(gravity=(9.81, 1, 1, 1)), ConfigError, "gravity"),
    ("negative gravity", _set(gravity=(-9.81, 0, 0, -1)), ConfigError, "gravity"),
    ("species without radius", _species(lambda s: {"material": s["material"]}), ConfigError, "'radius'"),
    ("species keyword misspelt", _species(lambda s: {**s, "raduis": R}), ConfigError, "'raduis'"),
    ("species style", _species(lambda s: {**s, "style": "ellipsoid"}), ConfigError, "style"),
    ("species density as text", _species(lambda s: {**s, "density": "1000"}), ConfigError, "density"),
    ("material key misspelt", _material(youngModulus=1e7), ConfigError, "'youngModulus'"),
    ("Poisson's ratio of 0.7", _material(poissonsRatio=0.7), ConfigError, "'poissonsRatio'"),
    ("restitution of 0", _material(coefficientRestitution=0), ConfigError, "'coefficientRestitution'"),
    ("modulus as text", _material(youngsModulus="1e7"), ConfigError, "'youngsModulus'"),
    ("friction as a bool", _material(coefficientFriction=True), ConfigError, "'coefficientFriction'"),
    ("negative density", _material(density=-1000), ConfigError, "'density'"),
    ("negative radius", _species(lambda s: {**s, "radius": -R}), ConfigError, "radius"),
    (
        "radius distribution",
        _species(lambda s: {**s, "radius": ("gauss", R, R / 10)}),
        ConfigError,
        "'gauss'",
    ),
    ("radii below zero", _species(lambda s: {**s, "radius": ("normal", R, R)}), ConfigError, "radius"),
    ("poly weights", _species(lambda s: {**s, "radius": ("poly", (R, R / 2), (1,))}), ConfigError, "radius"),
    (
        "radius of 1e-300 m",
        _species(lambda s: {**s, "radius": 1e-300}),
        ConfigError,
        "1e-300 m is outside the radii DEM describes, 1e-09 to 1000 m",
    ),
    (
        "lognormal radii over 600 orders of magnitude",
        _species(lambda s: {**s, "radius": ("lognormal", R, 300)}),
        ConfigError,
        "spans radii from 1e-394 to 1e388 m",
    ),
    ("nSim of 0", _set(nSim=0), ConfigError, "nSim"),
    ("two dimensions", _set(dim=2), ConfigError, "dim"),
    ("units", _set(units="cgs"), ConfigError, "units"),
    ("negative dt", _set(dt=-1e-5), ConfigError, "dt"),
    ("dt as text", _set(dt="1e-5"), ConfigError, "dt"),
    ("negative seed", _set(seed=-1), ConfigError, "seed"),
    ("no threads", _set(threads=0), ConfigError, "threads"),
    ("neighbour list type", _set(nns_type="binn"), ConfigError, "nns_type"),
    ("traj not a dict", _set(traj="traj.dump"), ConfigError, "traj"),
    ("traj keyword misspelt", _traj(pfil="traj.dump"), ConfigError, "'pfil'"),
    ("traj freq 0", _traj(freq=0), ConfigError, "traj freq"),
    ("traj style", _traj(style="customm"), ConfigError, "traj style"),
    ("traj sel 0", _traj(sel=0), ConfigError, "traj sel"),
    ("unknown traj column", _traj(pfile="t.dump", args=("id", "x", "radiuss")), ConfigError, "'radiuss'"),
    ("traj args one string", _traj(pfile="t.dump", args="id type x y z velocity"), ConfigError, "traj args"),
    (
        "traj column smuggling a command",
        _traj(pfile="t.dump", args=("id", "x\nshell touch X")),
        ConfigError,
        "traj args: 'x\\nshell touch X' holds '\\n'",
    ),
    ("restart keyword misspelt", _set(restart={"frq": 100}), ConfigError, "'frq'"),
    ("mesh not a dict", lambda p: {**p, "mesh": [str(square_stl(p))]}, ConfigError, "mesh"),
    (
        "mesh without file",
        lambda p: {**p, "mesh": {"plate": {"mtype": "mesh/surface"}}},
        ConfigError,
        "'file'",
    ),
    ("mesh file missing", lambda p: {**p, "mesh": {"plate": {"file": "none.stl"}}}, ConfigError, "none.stl"),
    (
        "mesh file a folder",
        lambda p: _mesh(file=str(Path(p["output"]).parent))(p),
        ConfigError,
        "is a folder",
    ),
    ("mesh file a device", _mesh(file="/dev/zero"), ConfigError, "/dev/zero is not a regular file"),
    ("output a file", _output_in("at"), ConfigError, "a file is in its place"),
    ("output under a file", _output_in("under"), ConfigError, "a file is in its place or in a parent's"),
    ("output with a line break", _set(output="out\nput"), ConfigError, "'out\\nput' holds the control"),
    ("mesh type", _mesh(mtype="mesh/surfac"), ConfigError, "mtype"),
    ("mesh keyword misspelt", _mesh(scael=1e-3), ConfigError, "'scael'"),
    ("mesh in millimetres", _mesh(), ConfigError, "'scale': 1e-3"),
    ("mesh outside the box", _mesh(scale=1e-3, move=(0.01, 0.01, 0.03)), ConfigError, "mesh 'plate'"),
    ("mesh partly outside the box", _mesh(scale=1e-3), ConfigError, "triangles lie outside the box"),
    ("traj style atom", _traj(style="atom"), UnsupportedFeature, "traj style 'atom'"),
    ("dump_modify without a dump file", _set(dump_modify=("sort", "id")), ConfigError, "dump_modify"),
    ("traj margs without meshes", _traj(mfile="mesh*.vtk", margs=("id",)), ConfigError, "traj margs"),
    (
        "traj style custom/vtk with a dump file",
        _traj(pfile="t.dump", style="custom/vtk"),
        ConfigError,
        ".vtk",
    ),
    ("engine misspelt", _set(engine="nativ"), PluginNotFound, "'nativ'"),
]

#: Centres of the particles the shared simulations start with (species 1, then species 2).
FIRST = (0.005, 0.005, 0.005)
CENTRES = {1: np.array([FIRST, (0.015, 0.005, 0.005)]), 2: np.array([(0.005, 0.015, 0.005)])}


def _remove_twice(sim: DEM) -> None:
    handle = sim.monitor(quantities=("n",), freq=10)
    sim.remove(handle)
    sim.remove(handle)


def _contact(sim):
    return sim.engine.time_step_check.limits.contact


#: (id, a call on the shared simulation, error class, what the message must name)
CALL = [
    ("insert keyword misspelt", lambda s: s.insert(1, value=10, regoin=None), ConfigError, "'regoin'"),
    (
        "insert mech misspelt",
        lambda s: s.insert(1, value=10, mech="particles_in_regon"),
        ConfigError,
        "'particles_in_regon'",
    ),
    ("insert without an amount", lambda s: s.insert(1), ConfigError, "value="),
    ("insert by rate without a rate", lambda s: s.insert(1, insert="by_rate"), ConfigError, "rate="),
    (
        "insert a volume fraction above 1",
        lambda s: s.insert(1, value=1.5, mech="volumefraction_region"),
        ConfigError,
        "1.5",
    ),
    ("insert weights", lambda s: s.insert((1, 2), value=10, weights=(0.5, 0.6)), ConfigError, "weights"),
    ("insert a species that does not exist", lambda s: s.insert(3, value=10), ConfigError, "species 3"),
    ("region type", lambda s: s.insert(1, value=10, region=("box", 0, 1, 0, 1, 0, 1)), ConfigError, "'box'"),
    (
        "region of two numbers",
        lambda s: s.insert(1, value=10, region=("block", 0, 1)),
        ConfigError,
        "'block'",
    ),
    (
        "cylinder region axis",
        lambda s: s.insert(1, value=10, region=("cylinder", "w", 0, 0, 1, 0, 1)),
        ConfigError,
        "'w'",
    ),
    ("empty region", lambda s: s.insert(1, value=10, region=("sphere", 0, 0, 0, 0)), ConfigError, "region"),
    ("velocity type", lambda s: s.insert(1, value=10, vel_type="uniformm"), ConfigError, "'uniformm'"),
    ("all_in as text", lambda s: s.insert(1, value=10, all_in="true"), ConfigError, "all_in"),
    ("createParticles style", lambda s: s.createParticles(1, "grid", 2e-3), ConfigError, "'grid'"),
    (
        "createParticles of all species",
        lambda s: s.createParticles("all", "single", *FIRST),
        ConfigError,
        "'all'",
    ),
    ("lattice without spacing", lambda s: s.createParticles(1, "lattice"), ConfigError, "spacing"),
    ("random without count", lambda s: s.createParticles(1, "random"), ConfigError, "count"),
    (
        "single with two coordinates",
        lambda s: s.createParticles(1, "single", 0.01, 0.01),
        ConfigError,
        "'single'",
    ),
    (
        "positions of two columns",
        lambda s: s.createParticles(1, "single", np.zeros((3, 2))),
        ConfigError,
        "positions",
    ),
    (
        "createParticles keyword misspelt",
        lambda s: s.createParticles(1, "single", 0.01, 0.01, 0.01, velocity=(1, 0, 0)),
        ConfigError,
        "'velocity'",
    ),
    (
        "a particle created on top of another",
        lambda s: s.createParticles(2, "single", *FIRST),
        ConfigError,
        "createParticles position",
    ),
    (
        "two new particles overlapping",
        lambda s: s.createParticles(2, "single", np.array([(0.015, 0.015, 0.015), (0.0155, 0.015, 0.015)])),
        ConfigError,
        "createParticles position",
    ),
    (
        "a particle created outside the box",
        lambda s: s.createParticles(1, "single", 0.03, 0.01, 0.01),
        ConfigError,
        "createParticles position (0.03, 0.01, 0.01) is outside the box",
    ),
    (
        "positions partly outside the box",
        lambda s: s.createParticles(2, "single", np.array([(0.015, 0.015, 0.015), (0.015, 0.015, -0.001)])),
        ConfigError,
        "createParticles position (0.015, 0.015, -0.001) is outside the box",
    ),
    (
        "lattice region through a face",
        lambda s: s.createParticles(1, "lattice", 4e-3, region=("block", -0.01, 0.01, 0, 0.02, 0, 0.02)),
        ConfigError,
        "createParticles region",
    ),
    (
        "random region above the box",
        lambda s: s.createParticles(1, "random", 5, region=("block", 0, 0.02, 0, 0.02, 0.01, 0.03)),
        ConfigError,
        "createParticles region",
    ),
    (
        "insertion region through a face",
        lambda s: s.insert(1, value=10, region=("block", -0.01, 0.01, 0, 0.02, 0, 0.02)),
        ConfigError,
        "insert region",
    ),
    (
        "insertion cylinder wider than the box",
        lambda s: s.insert(1, value=10, region=("cylinder", "z", 0.01, 0.01, 0.015, 0, 0.02)),
        ConfigError,
        "insert region",
    ),
    (
        "lattice spacing below one diameter",
        lambda s: s.createParticles(1, "lattice", 1e-3, region=("block", 0, 0.01, 0, 0.01, 0.01, 0.02)),
        ConfigError,
        "lattice spacing 0.001 is below one diameter (0.002)",
    ),
    (
        "lattice with no room for a particle",
        lambda s: s.createParticles(1, "lattice", 3e-3, region=("block", 0, 1e-3, 0, 0.02, 0, 0.02)),
        ConfigError,
        "no site of spacing 0.003",
    ),
    (
        "lattice on top of particles",
        lambda s: s.createParticles(
            1, "lattice", 2e-3, region=("block", 0.004, 0.008, 0.004, 0.008, 0.004, 0.008)
        ),
        ConfigError,
        "createParticles position",
    ),
    ("wall above the box", lambda s: s.setupWall(plane="zplane", peq=0.05), ConfigError, "peq=0.05"),
    ("wall below the box", lambda s: s.setupWall(plane="xplane", peq=-1e-3), ConfigError, "peq=-0.001"),
    ("wall type", lambda s: s.setupWall(wtype="plane", plane="zplane", peq=0.0), ConfigError, "wtype"),
    ("plane misspelt", lambda s: s.setupWall(plane="zplan", peq=0.0), ConfigError, "'zplan'"),
    ("plane without peq", lambda s: s.setupWall(plane="zplane"), ConfigError, "peq"),
    ("primitive wall without a plane", lambda s: s.setupWall(), ConfigError, "plane="),
    ("wall keyword", lambda s: s.setupWall(plane="zplane", peq=0.0, material={}), ConfigError, "'material'"),
    ("mesh wall without a mesh", lambda s: s.setupWall(wtype="mesh"), ConfigError, "mesh="),
    (
        "moving a mesh that does not exist",
        lambda s: s.moveMesh("hopper", linear=(0, 0, 1)),
        ConfigError,
        "'hopper'",
    ),
    ("addViscous without gamma", lambda s: s.addViscous(species=1), ConfigError, "gamma"),
    ("negative drag", lambda s: s.addViscous(gamma=-1.0), ConfigError, "gamma"),
    ("addViscous keyword misspelt", lambda s: s.addViscous(gamma=1.0, scal=2.0), ConfigError, "'scal'"),
    ("monitor quantity", lambda s: s.monitor(quantities=("kee",)), ConfigError, "'kee'"),
    ("monitor freq 0", lambda s: s.monitor(freq=0), ConfigError, "monitor freq"),
    ("monitor keyword misspelt", lambda s: s.monitor(frequency=10), ConfigError, "'frequency'"),
    ("set without a value", lambda s: s.set(species=1), ConfigError, "vel="),
    (
        "set ids no particle has",
        lambda s: s.set(ids=99, vel=(0, 0, 1)),
        ConfigError,
        "ids: no particle has id 99",
    ),
    ("set id 0", lambda s: s.set(ids=0, vel=(0, 0, 1)), ConfigError, "ids"),
    ("set keyword misspelt", lambda s: s.set(velocity=(0, 0, 1)), ConfigError, "'velocity'"),
    ("velocity with a radius", lambda s: s.velocity(radius=R), ConfigError, "radius"),
    ("extract an unknown quantity", lambda s: s.engine.extract("pos"), ConfigError, "'pos'"),
    ("remove twice", lambda s: _remove_twice(s), ConfigError, "already removed"),
    (
        "remove a foreign handle",
        lambda s: s.remove(Handle("wall", 1, "wall1", -1)),
        ConfigError,
        "not a handle",
    ),
    ("run no steps", lambda s: s.run(0), ConfigError, "nsteps"),
    ("run past the last step", lambda s: s.run(2**63), ConfigError, "the most the step counters hold"),
    (
        "insert beyond close packing",
        lambda s: s.insert(1, value=1e9, region=("block", 0, 0.006, 0, 0.006, 0, 0.006)),
        ConfigError,
        "1e+09 particles cannot fit",
    ),
    (
        "createParticles beyond close packing",
        lambda s: s.createParticles(1, "random", 10**12, region=("block", 0, 0.006, 0, 0.006, 0, 0.006)),
        ConfigError,
        "1e+12 particles cannot fit",
    ),
    (
        "createParticles radius of 1e-300 m",
        lambda s: s.createParticles(1, "single", 0.01, 0.01, 0.01, radius=1e-300),
        ConfigError,
        "radius 1e-300 m is outside the radii DEM describes",
    ),
    ("run negative steps", lambda s: s.run(-5), ConfigError, "nsteps"),
    ("run negative dt", lambda s: s.run(10, -1e-5), ConfigError, "dt"),
    ("dt 8 times the contact time", lambda s: s.run(10, 8 * _contact(s)), ConfigError, "dt = "),
    ("dt of 2 steps per contact", lambda s: s.run(10, 0.5 * _contact(s)), ConfigError, "dt = "),
    ("outflow face", lambda s: s.engine.expect_outflow("bottom"), ConfigError, "'bottom'"),
]


#: A mesh inside the box, for the settings of mesh output.
def _plate(p: dict[str, Any]) -> dict[str, Any]:
    return {"plate": {"file": str(square_stl(p)), "scale": 1e-3, "move": (0.01, 0.01, 0.01)}}


#: (id, change to the valid params, the capability that honours it, what the message must name);
#: a setting made of a mesh needs 'mesh-walls' first (see :data:`NEEDS`).
UNSUPPORTED = [
    (
        "dump_modify",
        lambda p: _traj(pfile="t.dump")(p) | {"dump_modify": ("sort id",)},
        "liggghts-dump",
        "dump_modify ('sort id',)",
    ),
    (
        "traj margs",
        lambda p: _traj(mfile="mesh*.vtk", margs=("id", "force"))(p) | {"mesh": _plate(p)},
        "liggghts-dump",
        "traj margs ('id', 'force')",
    ),
    ("neighbour list nsq", _set(nns_type="nsq"), "neighbor-styles", "nns_type='nsq'"),
]
#: What an ``UNSUPPORTED`` row's simulation needs besides its own capability (by row id).
NEEDS = {"traj margs": "mesh-walls"}


def running(
    output: Path, engine: str, model: type[ContactModel] = HertzMindlin, floor: bool = True, **options: Any
) -> DEM:
    """The simulation the ``CALL`` rows act on: particles of both species (at ``CENTRES``),
    a floor (for engines with plane walls), one step run."""
    sim = DEM(**valid(output, engine, model) | dict(options))
    if floor:
        sim.setupWall(species=1, plane="zplane", peq=0.0)
    for species, centres in CENTRES.items():
        sim.createParticles(species, "single", centres)
    sim.run(1)
    return sim
