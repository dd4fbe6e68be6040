"""The lap runner against plants whose lap time and errors are known exactly."""

from __future__ import annotations

import dataclasses
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial

import numpy as np
import pytest

from racing_lib.errors import PlantError
from racing_lib.experiments.lap import (
    LapMetrics,
    run_lap,
    run_trials,
    summarize,
)
from racing_lib.interfaces import Command, Observation
from racing_lib.model import identified_params
from racing_lib.tracks import circle_track


@dataclass
class Reference:
    path: object
    s: np.ndarray
    vx: np.ndarray


class RailPlant:
    """Moves along a path at constant speed and constant lateral offset: an ideal car on rails."""

    dt = 0.1

    def __init__(self, path, speed: float, offset: float = 0.0, start_s: float = 0.0):
        self.path, self.speed, self.offset, self.start_s = path, speed, offset, start_s
        self.s = start_s
        self.t = 0.0

    def _obs(self) -> Observation:
        x, y, psi = self.path.to_cartesian(self.s % self.path.length, self.offset, 0.0)
        return Observation(
            t=self.t, x=float(x), y=float(y), psi=float(psi), vx=self.speed, vy=0.0, r=0.0
        )

    def reset(self, seed=None) -> Observation:
        self.s, self.t = self.start_s, 0.0
        return self._obs()

    def step(self, steer_rad: float, pedal: float) -> Observation:
        self.s += self.speed * self.dt
        self.t += self.dt
        return self._obs()


class NaNPlant(RailPlant):
    def step(self, steer_rad: float, pedal: float) -> Observation:
        obs = super().step(steer_rad, pedal)
        return Observation(t=obs.t, x=float("nan"), y=obs.y, psi=obs.psi, vx=obs.vx, vy=0.0, r=0.0)


class Idle:
    def reset(self, obs):
        pass

    def step(self, obs):
        return Command(0.0, 0.0)

    def stats(self):
        return {}


@pytest.fixture(scope="module")
def circle():
    return circle_track(radius=100.0, width=12.0)


def _reference(track, v_ref: float) -> Reference:
    s = np.linspace(0.0, track.length, 200, endpoint=False)
    return Reference(track.centerline, s, np.full_like(s, v_ref))


def test_lap_time_of_a_car_on_rails_is_length_over_speed(circle):
    v = 20.0
    plant = RailPlant(circle.centerline, v, offset=0.0, start_s=circle.length - 50.0)
    result = run_lap(plant, Idle(), _reference(circle, v), track=circle)
    m = result.metrics
    assert m.completed
    # The crossing times are interpolated inside the step, so the lap time is exact.
    assert m.lap_time_s == pytest.approx(circle.length / v, abs=1e-6)
    assert m.vx_mae_mps == pytest.approx(0.0, abs=1e-12)


def test_errors_against_the_reference_are_measured(circle):
    v, offset = 25.0, 1.5
    plant = RailPlant(circle.centerline, v, offset=offset, start_s=circle.length - 30.0)
    m = run_lap(plant, Idle(), _reference(circle, v - 2.0), track=circle).metrics
    assert m.ey_mae_m == pytest.approx(offset, abs=1e-5)
    assert m.ey_max_m == pytest.approx(offset, abs=1e-5)
    assert m.vx_mae_mps == pytest.approx(2.0, abs=1e-9)
    # The rail plant advances s at v whatever its offset, so the lap still takes L / v.
    assert m.lap_time_s == pytest.approx(circle.length / v, rel=1e-6)


def test_a_lap_that_never_finishes_is_reported_not_completed(circle):
    plant = RailPlant(circle.centerline, 0.5, start_s=10.0)
    m = run_lap(plant, Idle(), _reference(circle, 20.0), track=circle, max_time=20.0).metrics
    assert not m.completed
    assert math.isnan(m.lap_time_s)
    assert m.to_dict()["lap_time_s"] is None


def test_a_plant_returning_nan_raises_a_clear_error(circle):
    plant = NaNPlant(circle.centerline, 20.0)
    with pytest.raises(PlantError, match="non-finite"):
        run_lap(plant, Idle(), _reference(circle, 20.0), track=circle)


def _rail_lap(track, v, seed) -> LapMetrics:
    plant = RailPlant(track.centerline, v + seed, start_s=track.length - 20.0)
    return run_lap(plant, Idle(), _reference(track, v), track=track, seed=seed).metrics


def test_trials_through_an_executor_match_serial(circle):
    fn = partial(_rail_lap, circle, 20.0)
    serial = run_trials(fn, [0, 1, 2])
    with ThreadPoolExecutor(max_workers=2) as pool:
        parallel = run_trials(fn, [0, 1, 2], executor=pool)
    assert [m.lap_time_s for m in serial] == [m.lap_time_s for m in parallel]
    summary = summarize(serial)
    assert summary["completed"] == 3
    expected = [circle.length / v for v in (20.0, 21.0, 22.0)]
    assert summary["lap_time_min_s"] == pytest.approx(min(expected), rel=1e-9)
    assert summary["lap_time_mean_s"] == pytest.approx(np.mean(expected), rel=1e-9)


@pytest.mark.parametrize("name", ["expressway", "shortcut"])
def test_nominal_controller_laps_each_builtin_track_cleanly(name):
    """Chapter 01's lap: the centerline at a moderate speed, no wall contact, nothing off track."""
    from racing_lib.control.nominal import MODERATE_SPEED_SCALE
    from racing_lib.experiments.lap import (
        LapSpec,
        drive_lap,
    )
    from racing_lib.planning.trajectory import Trajectory
    from racing_lib.tracks import load_track

    track = load_track(name)
    reference = Trajectory.from_centerline(track, identified_params()).scale_speed(
        MODERATE_SPEED_SCALE
    )
    m = drive_lap(LapSpec(track=track, trajectory=reference, controller="nominal"), seed=3).metrics
    assert m.completed
    assert m.wall_contacts == 0 and m.offtrack_time_s == 0.0
    assert m.lap_time_s == pytest.approx(reference.lap_time, rel=0.03)
    assert m.ey_max_m < 3.0


def test_a_non_finite_observation_is_refused_and_a_huge_finite_one_is_not():
    # The check adds the values first (one test a step); an overflowing sum of finite values must
    # still pass, and any NaN or infinity must still be named.
    from racing_lib.experiments.lap import _check_observation

    huge = Observation(0.0, 1e308, 1e308, 0.0, 1e308, 0.0, 0.0)
    _check_observation(huge, 3)
    for field in ("x", "vx", "r", "t"):
        for bad in (float("nan"), float("inf"), -float("inf")):
            obs = dataclasses.replace(huge, **{field: bad})
            with pytest.raises(PlantError, match="non-finite observation at step 3"):
                _check_observation(obs, 3)
