"""A stable-baselines3 vector env that steps its envs in two processes at once.

Render-free envs (``gt_cones``, ``surrogate``) take a fraction of a millisecond a step, too little for
SB3's ``SubprocVecEnv`` (one process and one pipe round trip per env) and too much to leave the
second core idle as ``DummyVecEnv`` does. :class:`SplitVecEnv` keeps the first envs in this process
and the rest in one worker process, each part a ``DummyVecEnv``; a step sends the worker its actions,
steps this process's half meanwhile, then joins the two. Env ``i`` is built, seeded and auto-reset
exactly as in ``DummyVecEnv``, so observations, rewards and infos are the same, and so is what PPO
learns from them.

Example:
    >>> from weather_gym.lab.training.policy.split_vec_env import split_point
    >>> split_point(8), split_point(4), split_point(2)
    (3, 2, 1)
"""

from __future__ import annotations

import multiprocessing as mp
import pickle
import signal
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnv, VecEnvIndices

from weather_gym.core.errors import InputError
from weather_gym.pipeline import start_method

CLOSE_TIMEOUT_S = 30.0
"""How long :meth:`SplitVecEnv.close` waits for the worker to close its envs before ending it."""


def split_point(num_envs: int) -> int:
    """How many of ``num_envs`` envs stay in the calling process: a little under half, because this
    process also runs the policy and SB3's bookkeeping while the worker waits (8 envs: 3 here, 5 in
    the worker trained PPO 5-9 % faster than 4 + 4 in three alternated pairs of runs)."""
    return max(1, num_envs // 2 - num_envs // 8)


def _worker(conn: Any, env_fns: CloudpickleWrapper) -> None:
    """The worker's loop: a ``DummyVecEnv`` of its envs, driven by ``(command, data)`` messages."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle,
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # and a stop sent to the whole group (systemd, kill -TERM -PGID)
    venv: DummyVecEnv = None  # type: ignore[assignment]  # the first command builds it
    while True:
        try:
            cmd, data = conn.recv()
        except (EOFError, OSError):  # the main process is gone
            break
        try:
            if cmd == "close":
                if venv is not None:
                    venv.close()
                _answer(conn, ("ok", None))
                break
            venv, result = _handle(venv, env_fns, cmd, data)
            reply: tuple[str, Any] = ("ok", result)
        except Exception as exc:  # noqa: BLE001 - sent to the main process and raised there
            reply = ("error", (_picklable(exc), traceback.format_exc()))
        if not _answer(conn, reply):
            break
    conn.close()


def _handle(venv: DummyVecEnv, env_fns: CloudpickleWrapper, cmd: str, data: Any) -> tuple[DummyVecEnv, Any]:
    """One command of the main process on the worker's envs: ``(the envs, the reply's value)``."""
    if cmd == "build":
        return DummyVecEnv(env_fns.var), None
    if cmd == "step":
        venv.step_async(data)
        return venv, (*venv.step_wait(), list(venv.reset_infos))
    if cmd == "reset":
        venv._seeds, venv._options = list(data[0]), list(data[1])
        return venv, (venv.reset(), list(venv.reset_infos))
    if cmd == "get_attr":
        return venv, venv.get_attr(data[0], data[1])
    if cmd == "set_attr":
        return venv, venv.set_attr(data[0], data[1], data[2])  # type: ignore[func-returns-value]  # the reply: None
    if cmd == "env_method":
        return venv, venv.env_method(data[0], *data[1], indices=data[3], **data[2])
    if cmd == "is_wrapped":
        return venv, [is_wrapped(venv.envs[i], data[0]) for i in data[1]]
    if cmd == "get_images":
        return venv, venv.get_images()
    raise RuntimeError(f"SplitVecEnv worker: unknown command {cmd!r} (a bug in weather-gym)")


def _answer(conn: Any, message: tuple[str, Any]) -> bool:
    """Send ``message`` to the main process; False when it stopped listening (it has gone, or gave up
    waiting for a slow close on a loaded machine): then there is no one to answer, and no traceback."""
    try:
        conn.send(message)
    except (BrokenPipeError, ConnectionResetError):
        return False
    return True


def _picklable(exc: Exception) -> Exception | None:
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001
        return None
    return exc


def _join(first: Any, second: Any) -> Any:
    """Concatenate two halves' observations (arrays, or dicts/tuples of arrays) along the env axis."""
    if isinstance(first, dict):
        return {k: np.concatenate([first[k], second[k]]) for k in first}
    if isinstance(first, tuple):
        return tuple(np.concatenate([a, b]) for a, b in zip(first, second, strict=True))
    return np.concatenate([first, second])


class SplitVecEnv(VecEnv):
    """Envs ``[0, local)`` stepped in this process and ``[local, n)`` in one worker process, at once.

    Args:
        env_fns: functions that build the envs (picklable with cloudpickle, like SB3's ``SubprocVecEnv``).
        local: how many envs stay in this process; default :func:`split_point` (a little under half).
        context: the worker's start method (None: ``forkserver``, or ``spawn`` where there is none, as
            SB3's ``SubprocVecEnv``; in a script, create the env under ``if __name__ == "__main__":``,
            or the worker starts with ``fork`` and a warning).

    Errors in the worker are raised here, with the worker's traceback as a note. Ctrl-C interrupts
    only this process; :meth:`close` then ends the worker.
    """

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], local: int | None = None,
                 context: str | None = None) -> None:
        n = len(env_fns)
        if n < 2:
            raise InputError(f"SplitVecEnv needs at least 2 envs (one per process), got {n}")
        local = split_point(n) if local is None else local
        if isinstance(local, bool) or not isinstance(local, int) or not 1 <= local < n:
            raise InputError(f"SplitVecEnv: local must be an integer in [1, {n - 1}] for {n} envs, got {local!r}")
        self._k = local
        self._remote_envs = f"envs {local}-{n - 1}"  # named in the worker's errors, also while building
        if context is None:  # as SB3's SubprocVecEnv: forkserver where the platform has it
            context = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx = mp.get_context(start_method(context, "SplitVecEnv"))
        self._conn, child = ctx.Pipe()
        self._process = ctx.Process(target=_worker, args=(child, CloudpickleWrapper(list(env_fns[local:]))),  # type: ignore[attr-defined]  # every start method's context has it
                                    daemon=True)
        self._process.start()
        child.close()
        self._closed = False
        self._pending = 0  # messages sent whose answer has not been read (Ctrl-C can leave one)
        try:
            self._send(("build", None))
            self._local = DummyVecEnv(list(env_fns[:local]))  # built while the worker builds its half
            self._receive()
        except BaseException:
            self._closed = True
            self._end_worker(ask=True)
            raise
        super().__init__(n, self._local.observation_space, self._local.action_space)

    # ------------------------------------------------------------------ worker messages
    def _stopped(self) -> RuntimeError:
        self._process.join(1.0)
        return RuntimeError(f"SplitVecEnv: the worker process (pid {self._process.pid}) stopped "
                            f"(exit code {self._process.exitcode})")

    def _send(self, message: tuple[str, Any]) -> None:
        try:
            self._conn.send(message)
        except (EOFError, OSError) as exc:
            raise self._stopped() from exc
        self._pending += 1

    def _receive(self) -> Any:
        try:
            status, data = self._conn.recv()
        except (EOFError, OSError) as exc:
            raise self._stopped() from exc
        self._pending -= 1
        if status == "error":
            exc, tb = data  # type: ignore[misc]  # the worker's exception, not an except clause's
            if exc is None:
                raise RuntimeError(f"SplitVecEnv: an env in the worker process failed:\n{tb}")
            exc.add_note(f"(raised in the SplitVecEnv worker process, {self._remote_envs}):\n{tb}")
            raise exc
        return data

    def _call(self, cmd: str, data: Any = None) -> Any:
        self._send((cmd, data))
        return self._receive()

    def _split(self, indices: VecEnvIndices) -> tuple[list[int], list[int], list[int]]:
        idx = list(self._get_indices(indices))
        return idx, [i for i in idx if i < self._k], [i - self._k for i in idx if i >= self._k]

    def _merge(self, idx: list[int], local: list[Any], remote: list[Any]) -> list[Any]:
        lo, re = iter(local), iter(remote)
        return [next(lo) if i < self._k else next(re) for i in idx]

    # ------------------------------------------------------------------ VecEnv
    def reset(self) -> Any:
        k = self._k
        self._send(("reset", (self._seeds[k:], self._options[k:])))
        self._local._seeds, self._local._options = self._seeds[:k], self._options[:k]
        obs = self._local.reset()
        remote_obs, remote_infos = self._receive()
        self.reset_infos = list(self._local.reset_infos) + remote_infos
        self._reset_seeds()
        self._reset_options()
        return _join(obs, remote_obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._send(("step", actions[self._k:]))
        self._local.step_async(actions[:self._k])

    def step_wait(self) -> Any:
        obs, rews, dones, infos = self._local.step_wait()  # meanwhile the worker steps its part
        r_obs, r_rews, r_dones, r_infos, r_reset_infos = self._receive()
        self.reset_infos = list(self._local.reset_infos) + r_reset_infos
        return (_join(obs, r_obs), np.concatenate([rews, r_rews]), np.concatenate([dones, r_dones]),
                list(infos) + list(r_infos))

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        idx, lo, re = self._split(indices)
        return self._merge(idx, self._local.get_attr(attr_name, lo) if lo else [],
                           self._call("get_attr", (attr_name, re)) if re else [])

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        _, lo, re = self._split(indices)
        if lo:
            self._local.set_attr(attr_name, value, lo)
        if re:
            self._call("set_attr", (attr_name, value, re))

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        idx, lo, re = self._split(indices)
        local = self._local.env_method(method_name, *method_args, indices=lo, **method_kwargs) if lo else []
        remote = self._call("env_method", (method_name, method_args, method_kwargs, re)) if re else []
        return self._merge(idx, local, remote)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        idx, lo, re = self._split(indices)
        return self._merge(idx, self._local.env_is_wrapped(wrapper_class, lo) if lo else [],
                           self._call("is_wrapped", (wrapper_class, re)) if re else [])

    def get_images(self) -> Sequence[np.ndarray | None]:
        return list(self._local.get_images()) + list(self._call("get_images"))

    def close(self) -> None:
        """Close both halves' envs and end the worker (safe to call twice)."""
        if self._closed:
            return
        self._closed = True
        try:
            while self._pending and self._conn.poll(CLOSE_TIMEOUT_S):  # answers an interruption left unread
                try:
                    self._receive()
                except Exception:  # noqa: BLE001 - an error of the interrupted call, no longer wanted
                    pass
            self._call("close")
        except (RuntimeError, OSError, EOFError):
            pass
        finally:
            self._local.close()
            self._end_worker()

    def _end_worker(self, ask: bool = False) -> None:
        if ask:  # the worker may still wait for commands: ask it to close its envs
            try:
                self._conn.send(("close", None))
            except (OSError, EOFError):
                pass
        self._process.join(CLOSE_TIMEOUT_S)
        if self._process.is_alive():
            self._process.kill()  # it ignores SIGTERM (see _worker)
            self._process.join()
        self._conn.close()
