"""The Gymnasium environment: the checker, registration, seeding, episodes' ends, vector envs."""

from __future__ import annotations

import subprocess
import sys
import warnings
from importlib.metadata import entry_points

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import racing_lib.envs
from racing_lib.envs import ENV_ID
from racing_lib.envs.time_trial import LOOKAHEAD, MPCPolicy, TimeTrialEnv
from racing_lib.errors import ArgumentError, RacingLibError
from racing_lib.tracks import CircuitSpec, load_track

SMALL = CircuitSpec(length=(1500.0, 2500.0))


def _roll(env, actions) -> tuple[list[np.ndarray], float, dict]:
    """Observations, return and the last info of an episode driven by ``actions(k)``."""
    obs, info = env.reset(seed=3)
    seen, total = [obs], 0.0
    for k in range(3000):
        obs, reward, terminated, truncated, info = env.step(actions(k))
        seen.append(obs)
        total += reward
        if terminated or truncated:
            break
    return seen, total, info


def test_passes_gymnasiums_env_checker_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gymnasium.make(ENV_ID).unwrapped)
        check_env(gymnasium.make(ENV_ID, track="generated", circuits=SMALL).unwrapped)


def test_made_by_id_in_a_fresh_interpreter_and_declared_as_an_entry_point():
    # Gymnasium >= 1.0 imports the module named before the colon, which registers the id.
    code = (
        "import gymnasium; env = gymnasium.make('racing_lib.envs:racing_lib/TimeTrial-v0', "
        "track='shortcut'); obs, _ = env.reset(seed=0); print(obs.shape, env.spec.id)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["(30,)", ENV_ID]
    # Gymnasium versions with a plugin loader (before 1.0) call this entry point of the installed
    # package when they are imported, so there the id alone is enough.
    (point,) = [e for e in entry_points(group="gymnasium.envs") if e.name == "racing_lib"]
    assert point.load() is racing_lib.envs.register_envs
    if int(gymnasium.__version__.split(".")[0]) < 1:
        plain = code.replace("racing_lib.envs:racing_lib/", "racing_lib/")
        out = subprocess.run([sys.executable, "-c", plain], capture_output=True, text=True)
        assert out.stdout.split() == ["(30,)", ENV_ID], out.stderr


def test_the_observation_is_the_documented_state():
    env = gymnasium.make(ENV_ID, track="expressway")
    obs, info = env.reset(seed=0)
    track = load_track("expressway")
    assert obs.shape == (10 + len(LOOKAHEAD),) and obs.dtype == np.float32
    assert obs[0] == pytest.approx(30.0)  # the rolling start
    assert obs[6] + obs[7] == pytest.approx(float(track.width_left(0.0) + track.width_right(0.0)))
    ahead = track.curvature(np.asarray(LOOKAHEAD))
    assert np.allclose(obs[10:], ahead, atol=1e-6)
    assert info["observation"].vx == pytest.approx(30.0)


def test_the_return_is_the_distance_driven_and_a_lap_ends_the_episode():
    env = gymnasium.make(ENV_ID, track="shortcut")
    policy = MPCPolicy()
    obs, info = env.reset(seed=0)
    policy.reset(env.unwrapped.track, info)
    total = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        total += reward
        if terminated or truncated:
            break
    assert info["end"] == "lap" and terminated and not truncated
    length = env.unwrapped.track.length
    assert length <= total < length + 60.0  # the last step ends just past the line
    plan_time = policy._plans[env.unwrapped.track.checksum()].lap_time
    # The MPC's lap from a 30 m/s rolling start: a few seconds slower than the flying plan.
    assert plan_time < info["lap_time_s"] < 1.1 * plan_time


def test_the_same_seed_gives_the_same_episode():
    env = TimeTrialEnv(track="expressway")
    env.action_space.seed(7)
    actions = [env.action_space.sample() * np.array([0.1, 1.0]) for _ in range(150)]
    first, ret1, _ = _roll(env, lambda k: actions[k % len(actions)])
    second, ret2, _ = _roll(env, lambda k: actions[k % len(actions)])
    assert ret1 == ret2 and all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    env.reset(seed=4)
    assert not np.array_equal(env.step(actions[0])[0], first[1])  # another seed, another car


@pytest.mark.parametrize(
    ("track", "steer", "end"),
    [("expressway", 1.0, "wall"), ("shortcut", -1.0, "off track")],
)
def test_leaving_the_road_ends_the_episode(track, steer, end):
    env = TimeTrialEnv(track=track)
    _, total, info = _roll(env, lambda k: np.array([steer, 0.2], dtype=np.float32))
    assert info["end"] in (end, "spin") and total < 300.0


def test_the_time_limit_truncates():
    env = gymnasium.make(ENV_ID, track="expressway", time_limit_s=3.0)
    env.reset(seed=0)
    for _ in range(100):
        _, _, terminated, truncated, info = env.step(np.array([0.0, -0.2], dtype=np.float32))
        if terminated or truncated:
            break
    assert truncated and not terminated and info["end"] == "time limit"
    assert info["time_s"] == pytest.approx(3.0, abs=0.11)
    with pytest.raises(ArgumentError, match="the episode has ended"):
        env.step(np.zeros(2, dtype=np.float32))


def test_generated_circuits_follow_the_episode_seed():
    env = TimeTrialEnv(track="generated", circuits=SMALL)
    env.reset(seed=1)
    a = env.track.length
    env.reset(seed=2)
    b = env.track.length
    env.reset(seed=1)
    assert env.track.length == a != b
    assert 1500.0 <= a <= 2500.0


@pytest.mark.parametrize("vector", ["sync", "async"])
def test_works_in_vector_environments(vector):
    make = gymnasium.vector.SyncVectorEnv if vector == "sync" else gymnasium.vector.AsyncVectorEnv
    envs = make([lambda: gymnasium.make(ENV_ID, track="shortcut")] * 2)
    try:
        obs, _ = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 30)
        for _ in range(20):
            obs, reward, terminated, truncated, _ = envs.step(np.tile([0.0, 0.5], (2, 1)))
        assert obs.shape == (2, 30) and np.all(reward > 0) and not terminated.any()
        assert not np.array_equal(obs[0], obs[1])  # two seeds, two cars
    finally:
        envs.close()


def test_a_foreign_car_drives_in_the_environment():
    pytest.importorskip("vehiclemodels")
    env = gymnasium.make(ENV_ID, track="shortcut", plant="commonroad:vehicle2")
    _, info = env.reset(seed=0)
    assert info["steer_max"] > 1.0  # the BMW's own steering limit (rad), not the simulated car's
    total = sum(env.step(np.array([0.0, 0.3], dtype=np.float32))[1] for _ in range(20))
    assert 40.0 < total < 120.0  # 2 s at about 30 m/s


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"plant": "kart"}, "unknown car"),
        ({"plant": 3}, "plant must be"),
        ({"start_speed": 0.0}, "start_speed"),
        ({"time_limit_s": -1.0}, "time_limit_s"),
        ({"track": "nowhere"}, "Unknown track"),
        ({"track": "generated", "circuits": CircuitSpec(length=(10.0, 20.0))}, "length range"),
        ({"track": "generated", "circuits": {"length": (2000, 3000)}}, "CircuitSpec"),
        ({"track": "shortcut", "circuits": CircuitSpec()}, "track='generated'"),
        ({"track": 3}, "track must be"),
        ({"start_speed": "30"}, "start_speed must be a number"),
        ({"steer_max": -0.5}, "steer_max must be a number > 0"),
        ({"time_limit_s": float("nan")}, "time_limit_s"),
        ({"lookahead": [10.0, -5.0]}, "lookahead"),
        ({"lookahead": "far"}, "lookahead"),
        ({"render_mode": "human"}, "does not render"),
    ],
)
def test_bad_arguments_get_one_clear_error(kwargs, words):
    with pytest.raises(RacingLibError, match=words):
        TimeTrialEnv(**kwargs)


def test_bad_actions_and_order_get_one_clear_error():
    env = TimeTrialEnv(track="shortcut")
    with pytest.raises(ArgumentError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    for action in ([0.0], [np.nan, 0.0], "go"):
        with pytest.raises(ArgumentError, match="steering, pedal"):
            env.step(action)
