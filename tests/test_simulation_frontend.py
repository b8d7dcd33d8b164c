"""simulation.DEM keyword validation into engine-neutral specs (no solver needed)."""

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest

from pygran_core import params, registry, simulation
from pygran_core.errors import ConfigError, PluginNotFound, PyGranError, UnsupportedFeature
from pygran_core.simulation import calls
from pygran_core.simulation.dem import resolve_engine, resolve_model
from pygran_core.simulation.models import HertzMindlin, SpringDashpot
from pygran_core.simulation.specs import (
    SIMULATION_KEYS,
    ServoSpec,
    parse_boundary,
    parse_gravity,
    parse_radius,
    parse_simulation,
)

DATA = Path(__file__).resolve().parent / "data"
MATERIAL = dict(params.glass, cohesionEnergyDensity=0.0)  # the toy engine has no cohesion
BASE = {"box": (0, 1e-2, 0, 1e-2, 0, 2e-2), "species": ({"material": MATERIAL, "radius": 5e-4},)}
#: A box around the test meshes however they are placed (a mesh outside the box is refused).
MESH_BOX = (-5, 5, -5, 5, -5, 5)


def spec(**overrides):
    return parse_simulation({**BASE, **overrides}, "toy", SpringDashpot)


def test_unknown_keyword_suggests_the_closest():
    with pytest.raises(ConfigError, match="Unknown simulation keyword 'boundry'. Did you mean 'boundary'"):
        spec(boundry=("p", "p", "f"))
    for typo, keyword in (("gravty", "gravity"), ("gravtiy", "gravity"), ("nsim", "nSim"), ("dtt", "dt")):
        with pytest.raises(ConfigError, match=f"'{typo}'. Did you mean '{keyword}'"):
            spec(**{typo: 1})


def test_the_scripts_own_keys_are_kept_apart():
    s = spec(stages={"insertion": 1e5, "run": 1e5}, nsteps=1e5, relax=True, run=2e4, T=300)
    assert s.user_keys == ("stages", "nsteps", "relax", "run", "T")
    assert spec().user_keys == ()
    with pytest.raises(ConfigError, match="'read_data' of PyGran 1.x is not supported: read the particles"):
        spec(read_data=("traj.dump", 0))
    with pytest.raises(ConfigError, match="Unknown species 1 keyword 'radus'. Did you mean 'radius'"):
        spec(species=({"material": MATERIAL, "radus": 1e-3},))


@pytest.mark.parametrize(
    ("value", "magnitude", "direction"),
    [
        ((9.81, 0, 0, -1), 9.81, (0, 0, -1)),
        ((0, 0, -1, 9.81), 9.81, (0, 0, -1)),
        ((9.81, 1, 0, 0), 9.81, (1, 0, 0)),
        ((0, 1, 0, 3), 3.0, (0, 1, 0)),
        ((1, 0, 0, 2), 2.0, (1, 0, 0)),
    ],
)
def test_gravity_either_order(value, magnitude, direction):
    gravity = parse_gravity(value)
    assert gravity.magnitude == magnitude and gravity.direction == direction
    np.testing.assert_allclose(gravity.vector, magnitude * np.array(direction))


@pytest.mark.parametrize("value", [(1, 0, 0, 1), (9.81, 0, 0, -9.81), (9.81, 0, 0), "down"])
def test_gravity_ambiguous_or_invalid(value):
    with pytest.raises(ConfigError, match="gravity"):
        parse_gravity(value)


def test_box_and_boundary():
    with pytest.raises(ConfigError, match="box: z lower bound 2.0 must be below the upper bound 1.0"):
        spec(box=(0, 1, 0, 1, 2, 1))
    with pytest.raises(ConfigError, match="box is required"):
        parse_simulation({}, "toy", SpringDashpot)
    assert parse_boundary(("p", "pp", "fs")) == ("p", "p", "fs")
    assert parse_boundary(("f", "ff", "m")) == ("f", "f", "m")
    assert spec(boundary=("p", "p", "f")).domain.periodic == (True, True, False)
    for bad, message in (
        (("p", "p"), "three flags"),
        (("p", "x", "f"), "not a flag"),
        (("pf", "p", "f"), "mixes"),
    ):
        with pytest.raises(ConfigError, match=message):
            parse_boundary(bad)


def test_radius_distributions_sample_what_they_promise():
    rng = np.random.default_rng(3)
    normal = parse_radius(("normal", 1e-4, 1e-5))
    radii = normal.sample(20000, rng)
    assert radii.mean() == pytest.approx(1e-4, rel=2e-3) and radii.std() == pytest.approx(1e-5, rel=0.05)
    assert radii.max() <= normal.max == pytest.approx(1.3e-4) and radii.min() >= normal.min
    lognormal = parse_radius(("lognormal", 1e-4, 0.2))
    assert lognormal.sample(20000, rng).mean() == pytest.approx(lognormal.mean, rel=5e-3)
    poly = parse_radius(("poly", (1e-4, 2e-4), (3, 1)))
    assert poly.weights == (0.75, 0.25) and poly.mean == pytest.approx(1.25e-4)
    assert np.mean(poly.sample(20000, rng) == 1e-4) == pytest.approx(0.75, abs=0.02)
    assert parse_radius(2e-3) == parse_radius(("constant", 2e-3))
    assert parse_radius(("gaussian", 1e-4, 1e-5)).kind == "normal"


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (-1e-3, "allows radii <= 0"),
        (("normal", 1e-4, 5e-5), "allows radii <= 0"),
        (("weibull", 1), "radius distribution"),
        (("poly", (1e-4,), (1, 2)), "as many weights"),
        (("constant",), "takes 1 values"),
        ("big", "radius must be"),
    ],
)
def test_bad_radius(value, message):
    with pytest.raises(ConfigError, match=message):
        parse_radius(value)


def test_species_material_is_validated():
    with pytest.raises(ConfigError, match="youngsModulus"):
        spec(species=({"material": dict(MATERIAL, youngsModulus=-1), "radius": 1e-3},))
    with pytest.raises(ConfigError, match="needs 'material' and 'radius'"):
        spec(species=({"radius": 1e-3},))
    one = spec(species=({"material": MATERIAL, "radius": 1e-3, "density": 1000},)).species[0]
    assert (
        one.density == 1000.0 and one.type == 1 and one.material["youngsModulus"] == MATERIAL["youngsModulus"]
    )


def test_output_and_files_resolved_against_cwd_without_chdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    s = spec(output="run1", traj={"pfile": "traj.h5", "mfile": "mesh*.vtk", "freq": 50, "dir": "frames"})
    assert s.output == tmp_path / "run1"
    assert s.traj.pfile == tmp_path / "run1" / "frames" / "traj.h5" and s.traj.freq == 50
    assert os.getcwd() == str(tmp_path)
    default = spec()
    assert default.output.name.startswith("SpringDashpot-") and default.traj.pfile.name == "traj.dump"
    with pytest.raises(ConfigError, match="Unknown traj keyword 'frq'. Did you mean 'freq'"):
        spec(traj={"frq": 10})


def test_restart_forms(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    manual = spec(output="o", restart=(500, "chk", "state.h5", True, None)).restart
    assert (manual.freq, manual.directory, manual.fname, manual.resume) == (
        500,
        tmp_path / "o" / "chk",
        "state.h5",
        True,
    )
    assert spec(restart=100).restart.freq == 100
    with pytest.raises(ConfigError, match="restart freq must be at least 1 step"):
        spec(restart=(0,))


def test_mesh_from_stl_with_liggghts_style_args(tmp_path, monkeypatch):
    silo = DATA / "meshes" / "silo.stl"
    mesh = spec(
        box=MESH_BOX,
        mesh={
            "hopper": {
                "file": str(silo),
                "mtype": "mesh/surface/stress",
                "material": MATERIAL,
                "args": ("scale 1e-3", "move 0 0 0.01", "rotate axis 0 0 1 angle 90"),
            }
        },
    ).meshes[0]
    assert (mesh.name, mesh.scale, mesh.translate, mesh.rotate) == (
        "hopper",
        1e-3,
        (0, 0, 0.01),
        ((0, 0, 1), 90.0),
    )
    as_dict = spec(box=MESH_BOX, mesh={"hopper": {"file": str(silo), "args": {"scale": 1e-3}}}).meshes[0]
    assert as_dict.scale == 1e-3 and as_dict.mtype == "mesh/surface"
    with pytest.raises(ConfigError, match="does not exist"):
        spec(box=MESH_BOX, mesh={"m": {"file": str(tmp_path / "none.stl")}})
    with pytest.raises(ConfigError, match="Unknown mesh 'm' argument 'scal'. Did you mean 'scale'"):
        spec(box=MESH_BOX, mesh={"m": {"file": str(silo), "args": ("scal 2",)}})


def _raw_points(name):
    from pygran_core.io import open_trajectory

    frame = open_trajectory(DATA / "meshes" / name, format="stl").read_frame(0)
    return frame.arrays["points"][frame.arrays["cells"][:, :3]]


def _turn(points, axis, degrees):
    from pygran_core.simulation.specs import rotation_matrix

    return points @ rotation_matrix(axis, degrees).T


def test_mesh_args_apply_in_the_order_written():
    side = str(DATA / "meshes" / "wall-2D-side.stl")
    raw = _raw_points("wall-2D-side.stl")
    move_first = spec(
        box=MESH_BOX, mesh={"w": {"file": side, "args": {"move": (0, 0, 1), "scale": 1e-3}}}
    ).meshes[0]
    scale_first = spec(
        box=MESH_BOX, mesh={"w": {"file": side, "args": {"scale": 1e-3, "move": (0, 0, 1)}}}
    ).meshes[0]
    np.testing.assert_allclose(move_first.triangles(), (raw + [0, 0, 1]) * 1e-3)
    np.testing.assert_allclose(scale_first.triangles(), raw * 1e-3 + [0, 0, 1])
    # the tuple form, and two rotations chained in one tuple as LIGGGHTS reads them
    once = {"scale": 1e-3, "rotate": ("axis", 0, 1, 0, "angle", 90), "move": (0, 0, 2e-3)}
    wall = spec(box=MESH_BOX, mesh={"w": {"file": side, "args": once}}).meshes[0]
    np.testing.assert_allclose(wall.triangles(), _turn(raw * 1e-3, (0, 1, 0), 90) + [0, 0, 2e-3], atol=1e-15)
    assert wall.rotate == ((0.0, 1.0, 0.0), 90.0)
    chained = dict(once, rotate=("axis", 1, 0, 0, "angle", -90, "rotate", "axis", 0, 1, 0, "angle", 90))
    expected = _turn(_turn(raw * 1e-3, (1, 0, 0), -90), (0, 1, 0), 90) + [0, 0, 2e-3]
    np.testing.assert_allclose(
        spec(box=MESH_BOX, mesh={"w": {"file": side, "args": chained}}).meshes[0].triangles(),
        expected,
        atol=1e-15,
    )
    words = spec(
        box=MESH_BOX,
        mesh={"w": {"file": side, "args": ("move 0 0 1", "rotate axis 0 0 1 angle 30", "scale 2")}},
    )
    np.testing.assert_allclose(
        words.meshes[0].triangles(), _turn(raw + [0, 0, 1], (0, 0, 1), 30) * 2, atol=1e-12
    )


def test_mesh_import_and_servo_keywords():
    side = str(DATA / "meshes" / "wall-2D-side.stl")
    assert spec(box=MESH_BOX, mesh={"w": {"file": side}}).meshes[0].wall is True
    assert spec(box=MESH_BOX, mesh={"w": {"file": side, "import": False}}).meshes[0].wall is False
    args = {
        "scale": 9.8e-4,
        "move": (0, 0, 6e-3),
        "com": (0, 0, 0),
        "axis": (0, 0, -2),
        "vel_max": 10.0,
        "ctrlPV": "force",
        "target_val": 5.0,
    }
    servo = spec(
        box=MESH_BOX, mesh={"PID": {"file": side, "mtype": "mesh/surface/stress/servo", "args": args}}
    ).meshes[0]
    assert servo.servo == ServoSpec(
        com=(0.0, 0.0, 0.0), control="force", axis=(0.0, 0.0, -1.0), target=5.0, vel_max=10.0
    )
    assert servo.scale == 9.8e-4 and servo.translate == (0.0, 0.0, 6e-3)
    assert (
        spec(box=MESH_BOX, mesh={"w": {"file": side, "mtype": "mesh/surface/stress"}}).meshes[0].servo is None
    )
    for mesh, message in (
        ({"args": {"scale": 1e-3, "temperature": 300}}, "Unknown mesh 'w' argument 'temperature'"),
        (
            {"args": {"vel_max": 1.0}},
            "'vel_max' is a servo keyword; it needs mtype='mesh/surface/stress/servo'",
        ),
        ({"args": {"move": "up"}}, "'move' takes 3 number"),
        ({"args": {"move": (0, 0)}}, "'move' takes 3 number"),
        ({"args": {"rotate": (0, 1, 0, 90)}}, "rotate is \\('axis', ax, ay, az, 'angle', degrees\\)"),
        ({"args": {"scale": -1}}, "scale must be > 0"),
        ({"args": {"scale": {1: 2}}}, "neither a keyword nor a number"),
        ({"import": "no"}, "'import' is True"),
        (
            {"mtype": "mesh/surface/stress/servo", "args": {"com": (0, 0, 0)}},
            "give ctrlPV, axis, target_val, vel_max",
        ),
        (
            {"mtype": "mesh/surface/stress/servo", "args": dict(args, ctrlPV="speed")},
            "Unknown mesh 'w' servo ctrlPV",
        ),
        ({"mtype": "mesh/surface/stress/servo", "args": dict(args, target_val=0)}, "must not be 0"),
        ({"mtype": "mesh/surface/stress/servo", "args": dict(args, mode="auto")}, "'auto' needs ratio > 0"),
        ({"file": 3}, "'file' must be a path"),
    ):
        with pytest.raises(ConfigError, match=message):
            spec(box=MESH_BOX, mesh={"w": {"file": side, **mesh}})


def test_mesh_motion_in_liggghts_move_mesh_forms():
    s = spec(
        box=MESH_BOX, mesh={"impeller": {"file": str(DATA / "meshes" / "valve.stl"), "args": {"scale": 1e-3}}}
    )
    original = calls.parse_motion(
        "impeller", {"rotate": ("origin", 1e-3, 0, 0), "axis": (0, 0, 2), "period": 5e-2}, s
    )
    assert (original.kind, original.origin, original.axis) == ("rotate", (1e-3, 0, 0), (0, 0, 1))
    assert original.omega == pytest.approx(2 * math.pi / 5e-2)
    words = calls.parse_motion("impeller", {"rotate": "origin 0.001 0 0 axis 0 0 1 period 0.05"}, s)
    assert words == original
    assert (
        calls.parse_motion(
            "impeller", {"rotate": True, "origin": (1e-3, 0, 0), "axis": (0, 0, 1), "omega": -1.0}, s
        ).omega
        == -1
    )
    with pytest.raises(ConfigError, match=r"moveMesh rotate needs axis=\(x, y, z\)"):  # as LIGGGHTS
        calls.parse_motion("impeller", {"rotate": ("origin", 0, 0, 0), "period": 0.1}, s)
    # PyGran 1.x's moveMesh(name, *args): LIGGGHTS' words, style first
    assert (
        calls.parse_motion(
            "impeller",
            calls.positional_motion(("rotate", "origin 0.001 0 0", "axis 0 0 1", "period 0.05")),
            s,
        )
        == original
    )
    assert calls.positional_motion(("linear", 0, 0, "-1e-3")) == {"linear": (0.0, 0.0, -1e-3)}
    with pytest.raises(ConfigError, match="a style .* first"):
        calls.positional_motion(("axis 0 0 1", "viblin"))
    wiggle = calls.parse_motion("impeller", {"wiggle": ("amplitude", 0, 0, 1e-4), "period": 0.01}, s)
    assert (wiggle.amplitude, wiggle.period) == ((0, 0, 1e-4), 0.01)
    assert (
        calls.parse_motion("impeller", {"wiggle": True, "amplitude": (0, 0, 1e-4), "period": 0.01}, s)
        == wiggle
    )
    # the original mixture demo: a plate tapped along z
    viblin = calls.parse_motion(
        "impeller",
        {"viblin": ("axis", 0, 0, 1), "order": 1, "amplitude": 12.5e-6, "phase": 0, "period": 0.025},
        s,
    )
    assert (viblin.axis, viblin.amplitudes, viblin.phases, viblin.periods) == (
        (0, 0, 1),
        (12.5e-6,),
        (0,),
        (0.025,),
    )
    vibrot = calls.parse_motion(
        "impeller",
        {
            "vibrot": ("origin", 0, 0, 1e-3),
            "axis": (1, 0, 0),
            "order": 2,
            "amplitude": (0.1, 0.05),
            "phase": (0, 1),
            "period": 0.1,
        },
        s,
    )
    assert (vibrot.origin, vibrot.amplitudes, vibrot.periods) == ((0, 0, 1e-3), (0.1, 0.05), (0.1, 0.1))
    for kwargs, message in (
        ({"rotate": ("origin", 0, 0, 0), "period": 0.1, "omega": 3}, "either period= \\(s\\) or omega="),
        ({"rotate": ("origin", 0, 0), "period": 0.1}, "origin must be a sequence of 3"),
        ({"rotate": ("origin", 0, 0, 0), "period": 0.1, "origin": (0, 0, 0)}, "'origin' is given twice"),
        ({"rotate": (0, 0, 0), "period": 0.1}, "expected the forms"),
        ({"rotate": ("origin", 0, 0, 0), "axes": (0, 0, 1), "period": 1}, "Did you mean 'axis'"),
        (
            {"wiggle": ("amplitude", 0, 0, 1), "period": 1, "axis": (0, 0, 1)},
            "wiggle takes amplitude, period, not 'axis'",
        ),
        ({"linear": (0, 0, 1), "period": 1}, "takes no 'period'"),
        (
            {"viblin": ("axis", 0, 0, 1), "order": 2, "amplitude": 1e-5, "phase": 0, "period": 1},
            "amplitude= with 2 value",
        ),
        ({"viblin": ("axis", 0, 0, 1), "order": 0.5, "amplitude": 1e-5, "phase": 0, "period": 1}, "order=n"),
        ({"riggle": ("origin", 0, 0, 0)}, "Unknown moveMesh keyword 'riggle'"),
        ({"linear": (0, 0, 1), "rotate": True, "period": 1}, "exactly one motion style"),
        ({"rotate": ("origin", 0, None, 0), "period": 1}, "neither a keyword nor a number"),
    ):
        with pytest.raises(ConfigError, match=message):
            calls.parse_motion("impeller", kwargs, s)


def test_step_counts_may_be_floats_truncated_as_liggghts_does():
    s = spec(traj={"freq": 1e3}, restart=(5e3, "restart", "r.h5", False, None))
    assert (s.traj.freq, s.restart.freq, s.notes) == (1000, 5000, ())
    third = spec(traj={"freq": 1e3 / 3}, restart=2500.5)
    assert (third.traj.freq, third.restart.freq) == (333, 2500)
    assert third.notes == (
        f"traj freq {1e3 / 3!r} truncated to 333 steps",
        "restart freq 2500.5 truncated to 2500 steps",
    )
    notes = []
    assert calls.parse_insert({"value": 10, "freq": 1e4}, s, 1, notes).freq == 10000 and notes == []
    assert calls.parse_monitor({"freq": 250.9}, notes).freq == 250 and notes == [
        "monitor freq 250.9 truncated to 250 steps"
    ]
    for bad, message in ((0.5, "at least 1 step"), ("1e5", "a number of steps"), (float("inf"), "a number")):
        with pytest.raises(ConfigError, match=f"traj freq must be {message}"):
            spec(traj={"freq": bad})


def test_numbers_may_be_int_or_float():
    s = spec(dt=1, nns_skin=1, box=(0, 1, 0, 1, 0, 1))
    assert s.dt == 1.0 and isinstance(s.dt, float) and s.skin == 1.0
    assert spec().skin == 5e-4
    with pytest.raises(ConfigError, match="dt must be a positive number"):
        spec(dt="1e-5")
    with pytest.raises(ConfigError, match="only 3-D"):
        spec(dim=2)
    with pytest.raises(ConfigError, match="Unknown units 'SI'"):
        spec(units="SI")


# -- per-call specs -----------------------------------------------------------------------


def test_regions():
    s = spec()
    block = calls.parse_region(("block", 0, 1, 0, 2, 0, 3), s)
    assert block.volume() == 6.0 and block.contains(np.array([[0.5, 1, 1], [2, 0, 0]])).tolist() == [
        True,
        False,
    ]
    cylinder = calls.parse_region(("cylinder", "z", 0, 0, 1, 0, 2), s)
    assert cylinder.volume() == pytest.approx(2 * math.pi)
    np.testing.assert_array_equal(cylinder.bounds(), [[-1, 1], [-1, 1], [0, 2]])
    assert cylinder.contains(np.array([[0.5, 0.5, 1.0], [0.9, 0.9, 1.0]]), margin=0.1).tolist() == [
        True,
        False,
    ]
    sphere = calls.parse_region(("sphere", 0, 0, 0, 2), s)
    assert sphere.volume() == pytest.approx(32 * math.pi / 3)
    assert calls.parse_region(None, s).volume() == pytest.approx(2e-6)
    with pytest.raises(ConfigError, match="Unknown region type 'cube'"):
        calls.parse_region(("cube", 1), s)
    with pytest.raises(ConfigError, match="takes 4 values"):
        calls.parse_region(("sphere", 0, 0, 1), s)


def test_insert_spec():
    s = spec()
    request = calls.parse_insert(
        {
            "species": 1,
            "value": 100,
            "region": ("block", 0, 1e-2, 0, 1e-2, 0, 1e-2),
            "vel_type": "uniform",
            "vel": (0, 0, -1, 0.1, 0.1, 0.1),
            "freq": 1000,
        },
        s,
        seed=7,
    )
    assert (request.mechanism, request.target, request.value, request.species, request.freq) == (
        "by_pack",
        "particles_in_region",
        100.0,
        (1,),
        1000,
    )
    velocities = request.velocity.sample(1000, np.random.default_rng(0))
    assert np.all(np.abs(velocities - (0, 0, -1)) <= 0.1)
    rate = calls.parse_insert(
        {"insert": "by_rate", "rate": 0.5, "rate_type": "massrate", "duration": 2}, s, 1
    )
    assert (rate.mechanism, rate.target, rate.value, rate.duration) == ("by_rate", "massrate", 0.5, 2.0)
    for bad, message in (
        ({"value": 10, "species": 3}, "species 3 does not exist"),
        ({}, "give the amount"),
        ({"value": 10.5}, "whole number"),
        ({"value": 1.2, "mech": "volumefraction_region"}, "above 1: give a fraction"),
        ({"value": 1, "vel": (0, 0)}, "vel \\(constant\\) must be a sequence of 3"),
        ({"value": 1, "regoin": None}, "Did you mean 'region'"),
    ):
        with pytest.raises(ConfigError, match=message):
            calls.parse_insert(bad, s, 1)


def test_insert_in_the_original_forms():
    s = spec()
    as_string = calls.parse_insert(
        {"value": 1.0, "mech": "volumefraction_region", "region": ("block", "0 1e-2 0 1e-2 0 5e-3")}, s, 1
    )
    nested = calls.parse_insert(
        {"value": 1.0, "mech": "volumefraction_region", "region": ("block", (0, 1e-2, 0, 1e-2, 0, 5e-3))},
        s,
        1,
    )
    assert as_string.region == nested.region == calls.Region("block", (0, 1e-2, 0, 1e-2, 0, 5e-3))
    assert as_string.value == 1.0 and as_string.requested == 1.0
    notes = []
    calls.parse_insert({"value": 0.9, "mech": "volumefraction_region"}, s, 1, notes)
    assert notes and "the region gets what fits" in notes[0]
    # PyGran 1.x by rate: a total and a rate per second
    total = calls.parse_insert({"insert": "by_rate", "mech": "nparticles", "value": 500, "rate": 1e4}, s, 1)
    assert (total.target, total.value, total.duration) == ("particlerate", 1e4, 0.05)
    mass = calls.parse_insert({"insert": "by_rate", "mech": "mass", "value": 1e-3, "rate": 0.1}, s, 1)
    assert (mass.target, mass.value, mass.duration) == ("massrate", 0.1, pytest.approx(0.01))
    assert calls.parse_insert({"value": 5, "all_in": "no"}, s, 1).all_in is False
    for bad, message in (
        ({"value": 5, "args": {"orientation": "random"}}, "species 1 is a sphere, which has no orientation"),
        ({"value": 5, "args": {"orient": "random"}}, "Did you mean 'orientation'"),
        ({"value": 5, "args": "orientation random"}, "args must be a dict"),
        ({"value": 5, "set_property": ("p", 1)}, "'set_property'.* is not supported"),
        ({"value": 5, "all_in": "maybe"}, "all_in must be 'yes' or 'no'"),
        ({"value": 5, "seed": "x"}, "seed must be a non-negative integer"),
        ({"value": 5, "weights": 1}, "weights must be 1 fractions"),
        ({"value": 5, "weights": ("a",)}, "insert weights must be a finite number"),
        (
            {"insert": "by_rate", "mech": "nparticles", "value": 500},
            "give the total as value=... and the rate",
        ),
        ({"value": 5, "region": ("block", "0 1 0 1 0")}, "takes 6 values"),
        ({"value": 5, "region": ("block", "a b c d e f")}, "block region must be a finite number"),
    ):
        with pytest.raises(ConfigError, match=message):
            calls.parse_insert(bad, s, 1)


def test_monitor_the_original_way_averages_as_liggghts_fix_ave_time():
    s = spec(species=({"material": MATERIAL, "radius": 5e-4}, {"material": MATERIAL, "radius": 5e-4}))
    average = calls.parse_average(
        {
            "var": "ke",
            "species": "all",
            "name": "ensemble_ke",
            "file": "ke.dat",
            "nevery": 100,
            "nrepeat": 10,
            "nfreq": 1e3,
        },
        s,
    )
    assert (average.quantity, average.species, average.nfreq) == ("ke", (1, 2), 1000)
    assert average.samples() == calls.MonitorSpec(("ke",), 100, "ensemble_ke-samples.txt")
    steps = np.arange(0, 2501, 100)
    values = steps.astype(float) ** 2
    out, means = average.average(steps, values, since=0)
    assert out.tolist() == [1000, 2000]  # 0 lacks the nine samples before it
    assert means.tolist() == [
        np.mean(np.arange(100, 1001, 100) ** 2.0),
        np.mean(np.arange(1100, 2001, 100) ** 2.0),
    ]
    once = calls.parse_average({"var": "erotate/sphere", "nevery": 10, "nfreq": 30}, s)
    assert (once.quantity, once.name, once.file, once.nrepeat) == (
        "ke_rot",
        "erotate_sphere",
        "erotate_sphere.dat",
        1,
    )
    assert once.average(np.arange(0, 100, 10), np.arange(10.0), since=0)[0].tolist() == [0, 30, 60, 90]
    assert once.average(np.arange(0, 100, 10), np.arange(10.0), since=40)[0].tolist() == [60, 90]
    for bad, message in (
        ({"var": "ke", "nevery": 100, "nfreq": 150}, "nfreq must be a multiple of nevery"),
        ({"var": "ke", "nevery": 100, "nrepeat": 20, "nfreq": 1000}, "nrepeat \\* nevery at most nfreq"),
        ({"var": "pe"}, "Unknown monitor var 'pe'"),
        ({"nevery": 10}, "needs var"),
        ({"var": "ke", "species": 3}, "species 3 does not exist"),
        ({"var": "ke", "name": "my ke"}, "name must be a word"),
        ({"var": "ke", "nevery": 0}, "monitor nevery must be at least 1 step"),
        ({"var": "ke", "freq": 10}, "Unknown monitor keyword 'freq'"),
    ):
        with pytest.raises(ConfigError, match=message):
            calls.parse_average(bad, s)


def test_multisphere_species_forms():
    organic = params.organic
    tablet = spec(
        species=(
            {
                "material": organic,
                "style": "multisphere/tablet",
                "nspheres": 12,
                "radius": 2e-2,
                "length": 1e-1,
            },
        )
    ).species[0]
    assert (tablet.style, len(tablet.spheres), tablet.radius.max, tablet.density) == (
        "multisphere",
        12,
        2e-2,
        1000.0,
    )
    x = np.array([sphere[0] for sphere in tablet.spheres])
    assert x.min() - 2e-2 == pytest.approx(-5e-2) and x.max() + 2e-2 == pytest.approx(5e-2)
    np.testing.assert_allclose(np.diff(x), (1e-1 - 4e-2) / 11)
    # PyGran 1.1 wrote the tablet as style 'multisphere'
    old = spec(
        species=(
            {"material": organic, "style": "multisphere", "nspheres": 12, "radius": 2e-2, "length": 1e-1},
        )
    )
    assert old.species[0].spheres == tablet.spheres

    def dumbbell():
        return [(-1e-3, 0, 0, 1e-3), (1e-3, 0, 0, 1e-3)]

    clump = spec(species=({"material": organic, "style": "multisphere", "function": dumbbell},)).species[0]
    assert clump.spheres == ((-1e-3, 0, 0, 1e-3), (1e-3, 0, 0, 1e-3)) and clump.radius.max == 1e-3
    for entry, message in (
        ({"style": "multisphere", "function": dumbbell, "radius": 1e-3}, "leave out radius"),
        ({"style": "multisphere", "function": lambda r: [(0, 0, 0, r)]}, "must take no arguments"),
        ({"style": "multisphere", "function": lambda: [(0, 0, 0)]}, "sphere 0 must be a sequence of 4"),
        ({"style": "multisphere", "function": lambda: [(0, 0, 0, -1)]}, "needs r > 0"),
        ({"style": "multisphere", "function": 3}, "must be a function"),
        ({"style": "multisphere/tablet", "nspheres": 3, "radius": 1e-3}, "missing length"),
        (
            {"style": "multisphere/tablet", "nspheres": 3, "radius": 1e-3, "length": 1e-2},
            "so that the spheres touch",
        ),
        (
            {"style": "multisphere/tablet", "nspheres": 2.5, "radius": 1e-3, "length": 3e-3},
            "nspheres must be a whole",
        ),
        ({"radius": 1e-3, "nspheres": 3}, "'nspheres' is for multisphere species"),
        ({"style": "multisphere", "nsphere": 3}, "Did you mean 'nspheres'"),
        ({"style": "ellipsoid", "radius": 1e-3}, "Unknown species 1 style 'ellipsoid'"),
    ):
        with pytest.raises(ConfigError, match=message):
            spec(species=({"material": organic, **entry},))


@pytest.mark.parametrize("other_mistake", [{}, {"gravty": (9.81, 0, 0, -1)}, {"box": "big"}, {"dt": -1}])
def test_an_engine_without_multisphere_says_so_first(tmp_path, monkeypatch, other_mistake):
    from pygran_native.engine import NativeEngine

    # every installed engine has clumps: take them away from native, in its class and its entry
    without = NativeEngine.capabilities - {"multisphere"}
    monkeypatch.setattr(NativeEngine, "capabilities", without)
    entry = dataclasses.replace(registry.get_engine("native"), capabilities=without)
    found = registry.get_engine
    monkeypatch.setattr(registry, "get_engine", lambda name: entry if name == "native" else found(name))
    species = (
        {
            "material": params.organic,
            "style": "multisphere/tablet",
            "nspheres": 4,
            "radius": 1e-3,
            "length": 6e-3,
        },
    )
    message = "The native engine does not support multisphere particles \\(capability 'multisphere'\\)"
    with pytest.raises(UnsupportedFeature, match=message):
        simulation.DEM(
            engine="native", **{**BASE, "species": species, "output": str(tmp_path), **other_mistake}
        )
    assert not any(tmp_path.iterdir())  # refused before anything started


def test_servo_walls_are_refused_before_anything_else_until_an_engine_has_them(tmp_path):
    side = str(DATA / "meshes" / "wall-2D-side.stl")
    servo = {
        "file": side,
        "mtype": "mesh/surface/stress/servo",
        "args": {"com": (0, 0, 0)},
    }  # incomplete, too
    with pytest.raises(UnsupportedFeature, match="servo walls .*capability 'servo-walls'"):
        simulation.DEM(engine="yade", **BASE, mesh={"plate": servo}, output=str(tmp_path))


def test_create_wall_motion_viscous_monitor_specs():
    silo = DATA / "meshes" / "silo.stl"
    s = spec(box=MESH_BOX, mesh={"hopper": {"file": str(silo), "args": {"scale": 1e-3}}})
    single = calls.parse_create(1, "single", (0, 0, 1e-2), {"vel": (0, 0, -0.1), "omega": (1, 0, 0)}, s, 3)
    assert single.position == (0, 0, 0.01) and single.velocity == (0, 0, -0.1) and single.omega == (1, 0, 0)
    with pytest.raises(
        ConfigError,
        match=r"x, y, z\) or \(species, .single., positions\) with an \(N, 3\) array: got \(0, 0\)",
    ):
        calls.parse_create(1, "single", (0, 0), {}, s, 3)
    assert (
        calls.parse_create(1, "random", (50,), {"region": ("block", 0, 1e-2, 0, 1e-2, 0, 1e-2)}, s, 3).count
        == 50
    )
    assert (
        calls.parse_wall({"wtype": "primitive", "species": 1, "plane": "planez", "peq": 0}, s).plane
        == "zplane"
    )
    assert calls.parse_wall({"wtype": "mesh"}, s).mesh == "hopper"
    with pytest.raises(ConfigError, match="needs peq"):
        calls.parse_wall({"plane": "zplane"}, s)
    rotate = calls.parse_motion("hopper", {"rotate": True, "axis": (0, 0, 2), "period": 0.5}, s)
    assert rotate.axis == (0, 0, 1) and rotate.omega == pytest.approx(4 * math.pi)
    assert calls.parse_motion("hopper", {"linear": (0, 0, -0.1)}, s).velocity == (0, 0, -0.1)
    with pytest.raises(ConfigError, match="Unknown mesh 'hoper'. Did you mean 'hopper'"):
        calls.parse_motion("hoper", {"linear": (0, 0, 1)}, s)
    with pytest.raises(ConfigError, match="exactly one motion style"):
        calls.parse_motion("hopper", {}, s)
    assert calls.parse_viscous({"gamma": 0.1}, s).species == (1,)
    assert calls.parse_monitor({"quantities": "ke", "freq": 10}).quantities == ("ke",)
    with pytest.raises(ConfigError, match="Unknown monitor quantity 'kee'"):
        calls.parse_monitor({"quantities": ("kee",)})


# -- DEM: engine and model resolution ------------------------------------------------------


def test_engine_resolution():
    assert resolve_engine(None) == "native"
    with pytest.raises(PluginNotFound, match="Did you mean 'liggghts'"):
        resolve_engine("ligghts")
    with pytest.raises(ConfigError, match="engine must be an engine's name"):
        resolve_engine(["native"])


def test_model_resolution():
    assert resolve_model("HertzMindlin") is HertzMindlin and resolve_model(SpringDashpot) is SpringDashpot
    with pytest.raises(PluginNotFound, match="No model named 'Hertz'"):
        resolve_model("Hertz")
    with pytest.raises(ConfigError, match="model must be a contact model class"):
        resolve_model(dict)


def test_dem_on_a_third_party_engine(with_plugins, tmp_path):
    with_plugins("pygran-toy")
    assert registry.lookup("engine", "toy")
    kwargs = {
        **BASE,
        "engine": "toy",
        "output": str(tmp_path / "o"),
        "dt": 1e-4,
        "progress": False,
        "seed": 5,
        "traj": {"pfile": None},
        "stages": {"settle": 20},
    }
    with simulation.DEM(**kwargs) as sim:
        assert sim.pargs["stages"] == {"settle": 20} and sim.pargs["engine"] == "toy"
        first = [sim._seed() for _ in range(3)]
        assert sim.createParticles(1, "single", 0.0, 0.0, 1e-2) == 1
        monitor = sim.monitor(quantities=("n",), freq=10)
        sim.run(2e1)
        assert monitor.values["n"].tolist() == [1, 1, 1]
        assert sim.step == 20 and sim.time == pytest.approx(2e-3)
        sim.run(50 / 3)  # LIGGGHTS truncates: 16 steps
        assert sim.step == 36
        sim.expect_outflow("z-")
        sim.run(4, check_dt=False)
        assert sim.step == 40
        with pytest.raises(UnsupportedFeature, match="toy engine does not support plane walls"):
            sim.setupWall(species=1, plane="zplane", peq=0.0)
    with simulation.DEM(**{**kwargs, "output": str(tmp_path / "p")}) as again:
        assert [again._seed() for _ in range(3)] == first
    log = (tmp_path / "o" / "pygran.log").read_text()
    assert "create CreateSpec(species=1, style='single'" in log and "run 20 steps" in log
    assert log.count("'stages'") == 1 and "keys of the script's own" in log
    assert f"run nsteps {50 / 3!r} truncated to 16 steps" in log and "run 20 steps" in log
    assert "outflow expected through z-" in log


def test_set_spec_selects_by_species_region_and_ids():
    s = spec(species=({"material": MATERIAL, "radius": 5e-4}, {"material": MATERIAL, "radius": 5e-4}))
    request = calls.parse_set(
        {"species": 2, "region": ("block", 0, 5e-3, 0, 1e-2, 0, 2e-2), "vel": (0, 0, 1)}, s
    )
    ids, types = np.array([1, 2, 3, 4]), np.array([1, 2, 2, 2])
    positions = np.array([[1e-3, 0, 0], [2e-3, 0, 0], [7e-3, 0, 0], [4e-3, 0, 0]])
    assert request.select(ids, types, positions).tolist() == [2, 4]
    assert calls.parse_set({"ids": 3, "radius": 1e-3}, s).select(ids, types, positions).tolist() == [3]
    for bad, message in (
        ({"species": 1}, "needs something to assign"),
        ({"ids": [0], "vel": (0, 0, 0)}, "ids must be"),
        ({"vel": (0, 0, 0), "spcies": 1}, "Did you mean 'species'"),
    ):
        with pytest.raises(ConfigError, match=message):
            calls.parse_set(bad, s)


BAD_VALUES = [
    None,
    "x",
    "1e5",
    -1,
    0,
    1.5,
    math.nan,
    math.inf,
    (),
    (1,),
    [1, 2, 3],
    {"a": 1},
    {1: 2},
    object(),
]
BAD_VALUES += [True, (None, None, None), ("a", "b", "c"), np.array([1.0, 2.0]), b"x", 10**30]
SERVO = {"com": (0, 0, 0), "ctrlPV": "force", "axis": (0, 0, 1), "target_val": 1, "vel_max": 1}
MULTISPHERE = {"material": MATERIAL, "style": "multisphere", "nspheres": 3, "radius": 1e-3, "length": 4e-3}


def _forms():
    """Every keyword of the forms PyGran parses, to be given each bad value in turn."""
    square = str(DATA / "meshes" / "square.stl")
    mesh = spec(box=MESH_BOX, mesh={"m": {"file": square}})
    yield from (("simulation", key, lambda v, k=key: spec(**{k: v})) for key in SIMULATION_KEYS)
    for key in ("style", "material", "density", "radius", "function", "nspheres", "length"):
        yield "species", key, lambda v, k=key: spec(species=({"material": MATERIAL, "radius": 5e-4, k: v},))
        yield "multisphere", key, lambda v, k=key: spec(species=(dict(MULTISPHERE, **{k: v}),))
    for key in ("file", "material", "mtype", "args", "import", "scale", "rotate", "move"):
        yield "mesh", key, lambda v, k=key: spec(box=MESH_BOX, mesh={"m": {"file": square, k: v}})
    servo = {"file": square, "mtype": "mesh/surface/stress/servo"}
    for key in ("move", "scale", "rotate", *SERVO, "kp", "mode", "ratio"):
        yield (
            "mesh args",
            key,
            lambda v, k=key: spec(box=MESH_BOX, mesh={"m": dict(servo, args=dict(SERVO, **{k: v}))}),
        )
    for key in ("freq", "dir", "pfile", "mfile", "sel", "style", "args", "margs"):
        yield "traj", key, lambda v, k=key: spec(traj={k: v})
    for key in calls.INSERT_KEYS:
        yield "insert", key, lambda v, k=key: calls.parse_insert({"value": 5, k: v}, mesh, 1)
        yield (
            "insert by rate",
            key,
            lambda v, k=key: calls.parse_insert({"insert": "by_rate", "rate": 5, k: v}, mesh, 1),
        )
    motions = (
        {"rotate": ("origin", 0, 0, 0), "period": 1},
        {"viblin": ("axis", 0, 0, 1), "order": 1, "amplitude": 1},
    )
    for key in (*calls.MOTION_STYLES, "origin", "axis", "period", "omega", "amplitude", "order", "phase"):
        for motion in motions:
            yield (
                "moveMesh",
                key,
                lambda v, k=key, m=motion: calls.parse_motion("m", {"phase": 0, **m, k: v}, mesh),
            )
    yield "moveMesh", "name", lambda v: calls.parse_motion(v, {"linear": (0, 0, 1)}, mesh)
    for key in calls.AVERAGE_KEYS:
        yield "old monitor", key, lambda v, k=key: calls.parse_average({"var": "ke", k: v}, mesh)
    for key in ("quantities", "freq", "file", "name"):
        yield "monitor", key, lambda v, k=key: calls.parse_monitor({k: v})
    for key in ("wtype", "species", "plane", "peq", "axis", "centre", "radius", "mesh"):
        yield "setupWall", key, lambda v, k=key: calls.parse_wall({"plane": "zplane", "peq": 0, k: v}, mesh)
    for key in ("gamma", "species", "scale"):
        yield "addViscous", key, lambda v, k=key: calls.parse_viscous({"gamma": 1, k: v}, mesh)
    for key in ("vel", "omega", "radius", "region", "spacing", "seed"):
        yield "createParticles", key, lambda v, k=key: calls.parse_create(1, "random", (5,), {k: v}, mesh, 1)
    for key in ("species", "region", "ids", "vel", "omega", "radius"):
        yield "set", key, lambda v, k=key: calls.parse_set({"vel": (0, 0, 0), k: v}, mesh)


def test_any_mistake_is_a_pygran_error():
    """Every keyword given every kind of wrong value: a PyGranError or nothing, never a bare
    TypeError, ValueError or MemoryError from inside."""
    failures = []
    for form, key, parse in _forms():
        for value in BAD_VALUES:
            try:
                parse(value)
            except PyGranError:
                pass
            except Exception as exc:  # noqa: BLE001 - any other exception is the defect tested for
                failures.append(f"{form} {key}={value!r}: {type(exc).__name__}: {exc}")
    assert not failures, "\n".join(failures[:20])
