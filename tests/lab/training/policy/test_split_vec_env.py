"""SplitVecEnv: envs in two processes at once, with what DummyVecEnv gives, the VecEnv API by index,
and clear errors from the worker."""

from __future__ import annotations

import os
import signal

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

from weather_gym.core.errors import InputError  # noqa: E402
from weather_gym.lab.training.policy.split_vec_env import SplitVecEnv  # noqa: E402


def _cartpoles(n: int) -> list:
    return [lambda: gym.wrappers.TimeLimit(gym.make("CartPole-v1"), 20) for _ in range(n)]


def _same(a, b, path="") -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), path
    else:
        assert a == b, (path, a, b)


def _rollout(vec, steps: int, actions) -> list:
    vec.seed(7)
    out = [vec.reset(), list(vec.reset_infos)]
    for t in range(steps):
        vec.step_async(actions(t))
        out += [vec.step_wait(), list(vec.reset_infos)]
    return out


@pytest.mark.slow
def test_surrogate_training_envs_step_exactly_as_in_one_process():
    """Observations, rewards, dones, infos (terminal observations included) and reset infos of the
    training envs, over episode ends, equal DummyVecEnv's, env by env."""
    from weather_gym.lab.training.policy.training_env import make_training_env

    tracks = ["hairpin", "oval", "peanut"]
    fns = [lambda t=t: make_training_env("WeatherGym/ConeTrack-v0", t, "surrogate", {}, 40, {}, None,
                                         surrogate_weather="droplets@2", lean_info=True) for t in tracks]
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, size=(100, 3, 2)).astype(np.float32)
    one = DummyVecEnv(fns)
    split = SplitVecEnv(fns)
    try:
        a, b = _rollout(one, 100, lambda t: acts[t]), _rollout(split, 100, lambda t: acts[t])
    finally:
        one.close()
        split.close()
    assert sum(int(d.sum()) for _, _, d, _ in a[2::2]) >= 3  # episodes ended and restarted on the way
    _same(a, b)


@pytest.mark.slow
def test_ppo_learns_the_same_weights_as_with_one_process():
    from stable_baselines3 import PPO

    from weather_gym.agents.sb3_features import ConeListPolicy
    from weather_gym.lab.training.policy.training_env import make_training_env

    fns = [lambda t=t: make_training_env("WeatherGym/ConeTrack-v0", t, "gt_cones", {}, 50, {}, None,
                                         lean_info=True) for t in ("hairpin", "oval", "b_shape")]
    weights = []
    for cls in (DummyVecEnv, SplitVecEnv):
        vec = cls(fns)
        try:
            model = PPO(ConeListPolicy, vec, n_steps=32, batch_size=48, n_epochs=2, seed=3, device="cpu")
            model.learn(192)
            weights.append({k: v.clone() for k, v in model.policy.state_dict().items()})
        finally:
            vec.close()
    assert all(np.array_equal(weights[0][k].numpy(), weights[1][k].numpy()) for k in weights[0])


def test_attributes_methods_and_wrappers_by_index():
    vec = SplitVecEnv(_cartpoles(5), local=2)
    try:
        assert vec.num_envs == 5 and vec._k == 2
        vec.set_attr("tag", "x", indices=[1, 3])
        assert vec.get_attr("tag", indices=[3, 1]) == ["x", "x"]
        with pytest.raises(AttributeError):
            vec.get_attr("tag", indices=[4])  # only 1 and 3 were set: the worker's error, raised here
        assert vec.env_method("get_wrapper_attr", "tag", indices=[1, 3]) == ["x", "x"]
        assert vec.env_is_wrapped(gym.wrappers.TimeLimit) == [True] * 5
        assert vec.get_attr("spec", indices=[4, 0])[0].id == "CartPole-v1"
        vec.seed(3)
        first = vec.reset()
        vec.seed(3)
        assert np.array_equal(first, vec.reset()) and first.shape == (5, 4)
    finally:
        vec.close()
        vec.close()  # twice is fine


def test_an_error_in_the_worker_is_raised_with_its_traceback():
    vec = SplitVecEnv(_cartpoles(2))
    try:
        vec.reset()
        vec.step_async(np.array([0, 7]))  # env 1 (the worker's) gets an invalid action
        with pytest.raises(AssertionError) as info:
            vec.step_wait()
        assert "SplitVecEnv worker process" in "".join(getattr(info.value, "__notes__", []))
    finally:
        vec.close()


def test_the_worker_starts_with_spawn_where_there_is_no_forkserver(monkeypatch):
    import multiprocessing

    started = []
    real = multiprocessing.get_context

    def spy(method=None):
        started.append(method)
        return real(method)

    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])
    monkeypatch.setattr(multiprocessing, "get_context", spy)
    vec = SplitVecEnv(_cartpoles(2))
    try:
        assert started == ["spawn"] and vec.reset().shape == (2, 4)
    finally:
        vec.close()


def test_close_after_an_unfinished_step_takes_the_answer_and_ends_the_worker():
    vec = SplitVecEnv(_cartpoles(3))
    vec.reset()
    vec.step_async(np.array([0, 1, 1]))  # as if Ctrl-C came before step_wait
    vec.close()
    assert not vec._process.is_alive() and vec._process.exitcode == 0


def test_an_env_that_fails_to_build_in_the_worker_is_raised_with_its_error():
    fns = [lambda: gym.make("CartPole-v1"), lambda: gym.make("NoSuchEnv-v0")]
    with pytest.raises(gym.error.Error) as info:
        SplitVecEnv(fns)
    assert "SplitVecEnv worker process, envs 1-1" in "".join(getattr(info.value, "__notes__", []))


def test_a_dead_worker_is_reported_not_waited_for():
    vec = SplitVecEnv(_cartpoles(2))
    try:
        vec.reset()
        os.kill(vec._process.pid, signal.SIGKILL)
        vec._process.join()
        with pytest.raises(RuntimeError, match="worker process .* stopped"):
            vec.step(np.array([0, 1]))
    finally:
        vec.close()


@pytest.mark.parametrize("n, local, message", [(1, None, "at least 2 envs"), (3, 3, r"local must be .* \[1, 2\]"),
                                               (3, 0, "got 0")])
def test_bad_sizes_are_refused(n, local, message):
    with pytest.raises(InputError, match=message):
        SplitVecEnv(_cartpoles(n), local=local)


def test_auto_vectorisation():
    from weather_gym.lab.training.policy.train import vec_kind

    assert vec_kind("auto", "surrogate", 8, cores=2) == "split"
    assert vec_kind("auto", "gt_cones", 8, cores=1) == "dummy"
    assert vec_kind("auto", "gt_cones", 1, cores=2) == "dummy"
    assert vec_kind("auto", "detector", 8, cores=16) == "dummy"
    assert vec_kind("subproc", "surrogate", 8, cores=2) == "subproc"
    with pytest.raises(InputError, match="--vec must be one of"):
        vec_kind("threads", "surrogate", 8)
