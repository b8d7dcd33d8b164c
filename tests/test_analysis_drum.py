"""The dynamic angle of repose of a drum's bed (analysis.drum.repose_angle), on constructed
beds of known angle: points filling a drum below a tilted plane."""

import numpy as np
import pytest

from pygran_core.analysis.drum import repose_angle
from pygran_core.errors import ConfigError

RADIUS, LENGTH = 0.05, 0.04


def bed(angle: float, fill: float, count: int = 20000, seed: int = 1) -> np.ndarray:
    """``count`` random points in a drum along y (radius 5 cm, 4 cm long) filling ``fill`` of
    it below a plane through the x axis's line at the right height, rising at ``angle``
    degrees towards -x (the side a drum turning right-handed about +y lifts)."""
    rng = np.random.default_rng(seed)
    xz = rng.uniform(-RADIUS, RADIUS, (8 * count, 2))
    xz = xz[np.hypot(*xz.T) < RADIUS]
    slope = np.tan(np.radians(angle))
    # the height across the surface, then the level leaving ``fill`` of the disc below it
    across = xz[:, 1] + slope * xz[:, 0]
    below = xz[across < np.quantile(across, fill)][:count]
    y = rng.uniform(-LENGTH / 2, LENGTH / 2, len(below))
    return np.column_stack((below[:, 0], y, below[:, 1]))


@pytest.mark.parametrize("fill", [0.15, 0.35, 0.6])
@pytest.mark.parametrize("angle", [0.0, 12.0, 35.0, 52.0])
def test_the_angle_of_a_bed_below_a_tilted_plane(angle, fill):
    assert repose_angle(bed(angle, fill)) == pytest.approx(angle, abs=0.8)


def test_the_sign_tells_the_sense_of_rotation():
    """Mirrored (x -> -x), the bed is the one a drum turning the other way makes; about the
    axis -y, that is the positive sense again."""
    points = bed(30.0, 0.3) * [-1, 1, 1]
    assert repose_angle(points) == pytest.approx(-30.0, abs=0.8)
    assert repose_angle(points, axis=(0, -1, 0)) == pytest.approx(30.0, abs=0.8)


def test_any_axis_and_up_and_any_place():
    """The same bed turned so that the drum's axis is x and gravity along -y, and moved: the
    angle is measured in the drum's cross-section whatever the frame."""
    points = bed(25.0, 0.3)
    turn = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]])  # a rotation: y -> x, z -> y, x -> z
    moved = points @ turn + [3.0, -1.0, 2.0]
    assert repose_angle(moved, axis=(10, 0, 0), up=(0, 2, 0)) == pytest.approx(25.0, abs=0.8)


def test_a_few_particles_in_flight_move_the_angle_little():
    """One particle in a hundred anywhere in the drum's upper half."""
    points = bed(40.0, 0.3)
    rng = np.random.default_rng(2)
    count = len(points) // 100
    flying = np.column_stack(
        (rng.uniform(-0.03, 0.03, count), rng.uniform(-0.02, 0.02, count), rng.uniform(0.0, 0.04, count))
    )
    assert repose_angle(np.vstack((points, flying))) == pytest.approx(40.0, abs=1.5)


def test_a_bed_without_a_surface_direction_is_refused():
    full = bed(20.0, 0.95)
    with pytest.raises(ConfigError, match="no clear surface direction"):
        repose_angle(full)


@pytest.mark.parametrize(
    ("positions", "kwargs", "match"),
    [
        (np.zeros((5, 2)), {}, r"\(N, 3\) array"),
        (np.zeros((2, 3)), {}, "N >= 3"),
        (bed(20.0, 0.3), {"axis": (0, 0, 0)}, "axis must be a non-zero 3-vector"),
        (bed(20.0, 0.3), {"up": (0, 2, 0)}, "is along the drum's axis"),
    ],
)
def test_bad_input_names_the_problem(positions, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        repose_angle(positions, **kwargs)
