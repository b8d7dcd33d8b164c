"""dynamics.Temporal: series, flow rate, mean square displacement, granular temperature."""

import numpy as np
import pytest

from pygran_core.analysis import System, dynamics
from pygran_core.io import Frame, open_writer

DT = 1e-3  # simulation time step
EVERY = 10  # steps between frames


def write(path, frames):
    with open_writer(path) as writer:
        for k, arrays in enumerate(frames):
            writer.write_frame(Frame(arrays, timestep=k * EVERY, box=np.array([[-10, 10.0]] * 3)))
    return System(Particles=str(path))


def particles(ids, positions, velocities=None, radius=0.1):
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    velocities = np.broadcast_to(
        0.0 if velocities is None else np.asarray(velocities, float), positions.shape
    )
    n = len(positions)
    return {
        "id": np.asarray(ids, dtype=int),
        **{c: positions[:, j] for j, c in enumerate("xyz")},
        "radius": np.full(n, radius),
        **{f"v{c}": velocities[:, j] for j, c in enumerate("xyz")},
    }


@pytest.fixture
def stream(tmp_path):
    """Particles falling at speed v through z = 0, spaced so that one crosses per frame interval."""
    v, t_frame = 2.0, EVERY * DT
    spacing = v * t_frame
    frames = []
    for k in range(6):
        ids = np.arange(1, 41)
        z = 0.1 - spacing * (ids - 1) - v * k * t_frame + spacing / 3  # never exactly on the plane
        frames.append(particles(ids, np.column_stack((np.zeros(40), np.zeros(40), z)), [0, 0, -v]))
    return write(tmp_path / "stream.dump", frames), v / spacing


def test_flow_rate_of_a_constant_velocity_stream(stream):
    system, rate = stream
    system.goto(3)
    temporal = dynamics.Temporal(system)
    times, count_rate = temporal.flowRate(point=(0, 0, 0), normal=(0, 0, -1), dt=DT)
    np.testing.assert_allclose(times, (np.arange(5) + 0.5) * EVERY * DT)
    np.testing.assert_allclose(count_rate, rate)
    _, mass_rate = temporal.flowRate((0, 0, 0), (0, 0, -1), dt=DT, density=1000.0)
    np.testing.assert_allclose(mass_rate, rate * 1000.0 * 4 / 3 * np.pi * 0.1**3)
    _, upward = temporal.flowRate((0, 0, 0), (0, 0, 1), dt=DT)
    np.testing.assert_allclose(upward, -rate)
    assert system.frame == 3  # left where it was


def test_flow_rate_over_many_frames_matches_the_stream(tmp_path):
    v, spacing, t_frame = 1.0, 0.25, EVERY * DT
    ids, zeros = np.arange(1, 401), np.zeros(400)
    frames = [
        particles(ids, np.column_stack((zeros, zeros, 2 - spacing * ids - v * k * t_frame + 1e-4)))
        for k in range(101)
    ]
    temporal = dynamics.Temporal(write(tmp_path / "long.dump", frames))
    _, rate = temporal.flowRate((0, 0, 0), (0, 0, -1), dt=DT)
    assert rate.mean() == pytest.approx(v / spacing, rel=0.03)


def test_series_of_attributes_methods_and_functions(stream):
    system, _ = stream
    temporal = dynamics.Temporal(system)
    np.testing.assert_array_equal(temporal.series("timestep"), np.arange(6) * EVERY)
    assert temporal.series("z").shape == (6, 40)
    np.testing.assert_allclose(np.diff(temporal.series("computeCOM")[:, 2]), -2.0 * EVERY * DT, rtol=1e-9)
    np.testing.assert_array_equal(temporal.series(len), [40] * 6)
    with pytest.raises(AttributeError, match="no attribute 'temperature'"):
        temporal.series("temperature")
    with pytest.raises(ValueError, match="the frames carry no time; pass dt="):
        temporal.flowRate((0, 0, 0), (0, 0, 1))
    with pytest.raises(ValueError, match="has no 'Mesh'"):
        dynamics.Temporal(system, "Mesh")


def test_series_with_varying_numbers_is_a_list(tmp_path):
    frames = [particles(np.arange(1, n + 1), np.zeros((n, 3))) for n in (0, 3, 2)]
    series = dynamics.Temporal(write(tmp_path / "vary.dump", frames)).series("id")
    assert isinstance(series, list) and [len(s) for s in series] == [0, 3, 2]


def test_mean_square_displacement_ballistic_and_matched_by_id(tmp_path):
    v = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]])
    frames = [particles(np.zeros(0), np.zeros((0, 3)))]  # empty first frame, as in the hopper
    for k in range(1, 5):
        t = (k - 1) * EVERY * DT
        order = np.roll(np.arange(3), k)  # ids come in a different order each frame
        ids = np.array([7, 8, 9])[order]
        frames.append(particles(ids, (v * t)[order], v[order]))
    frames[-1] = {key: value[:2] for key, value in frames[-1].items()}  # one particle has left
    temporal = dynamics.Temporal(write(tmp_path / "msd.dump", frames))
    times, msd = temporal.meanSquareDisplacement(dt=DT)
    assert np.isnan(msd[0])
    left = np.array([7, 8, 9])[np.roll(np.arange(3), 4)][:2]
    speeds2 = {7: 1.0, 8: 4.0, 9: 9.0}
    expected = [14 / 3 * t**2 for t in times[1:4]] + [np.mean([speeds2[i] for i in left]) * times[4] ** 2]
    np.testing.assert_allclose(msd[1:], expected)
    np.testing.assert_allclose(times, (np.arange(5) - 1) * EVERY * DT)


def test_granular_temperature_of_gaussian_velocities(tmp_path):
    rng = np.random.default_rng(4)
    sigma = 0.3
    frames = [particles(np.zeros(0), np.zeros((0, 3)))]
    for _ in range(2):
        velocity = rng.normal(0, sigma, (20000, 3)) + [5.0, 0, -1.0]  # mean flow is not temperature
        frames.append(particles(np.arange(1, 20001), np.zeros((20000, 3)), velocity))
    temperature = dynamics.Temporal(write(tmp_path / "gas.dump", frames)).granularTemperature()
    assert np.isnan(temperature[0])
    np.testing.assert_allclose(temperature[1:], sigma**2, rtol=0.03)
