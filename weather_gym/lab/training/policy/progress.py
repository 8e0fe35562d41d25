"""What ``weather-gym train`` tells its user while it runs, and how it picks the model it keeps.

:class:`RunLog` prints a line (flushed, so a log file shows it at once) and appends it to the run's
``train.log``; :class:`Selector` drives the policy on the held-out drives
(:mod:`weather_gym.lab.training.policy.selection`) and keeps the best; :func:`ppo_callbacks` are the
SB3 callbacks that print PPO's progress and main statistics every rollout and call the selector every
``eval_freq`` steps.

Example:
    >>> import tempfile
    >>> log = RunLog(Path(tempfile.mkdtemp()) / "train.log", echo=False)
    >>> log("pretrain round 0: 300 steps")
    >>> log.path.read_text().split("] ", 1)[1]
    'pretrain round 0: 300 steps\\n'
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from weather_gym.core._io import atomic_path, atomic_write_json
from weather_gym.lab.training.policy.selection import HeldOutResult

__all__ = ["RunLog", "Selector", "ppo_callbacks", "recorded_best"]


class RunLog:
    """Print ``message`` with the time of day and append it to ``path`` (the run's ``train.log``)."""

    def __init__(self, path: Path, echo: bool = True) -> None:
        self.path = Path(path)
        self.echo = echo

    def __call__(self, message: str) -> None:
        line = f"[{time.strftime('%Y-%m-%d %H:%M:%S')}] {message}"
        if self.echo:
            print(line, flush=True)
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write(line + "\n")


def recorded_best(best_json: Path) -> tuple | None:
    """The held-out score of the best model a run recorded (``best/best_model.json``), or None."""
    try:
        meta = json.loads(best_json.read_text(encoding="utf-8"))
        return tuple(meta["held_out"]["score"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


class Selector:
    """Drive a model on the held-out drives (``evaluate(model) -> HeldOutResult``) and write the best so
    far to ``best/best_model.zip`` with its JSON (``meta(steps)`` plus the held-out record)."""

    def __init__(self, evaluate: Callable[[Any], HeldOutResult], best_dir: Path,
                 meta: Callable[[int], dict[str, Any]], log: Callable[[str], None], best: tuple | None = None) -> None:
        self._evaluate, self.best_dir, self.meta, self.log = evaluate, Path(best_dir), meta, log
        self.best = best
        self.last_steps: int | None = None

    def evaluate(self, model: Any, logger: Any = None) -> HeldOutResult:
        steps = int(model.num_timesteps)
        t0 = time.time()
        result = self._evaluate(model)
        self.last_steps = steps
        new = self.best is None or result.score() > tuple(self.best)
        self.log(f"held-out drives at {steps} PPO steps: {result.summary()} ({time.time() - t0:.0f} s)"
                 + ("; the best so far: saved to best/" if new else f"; best so far: {self._describe(self.best)}"))
        if logger is not None:
            for key, value in (("eval/laps", result.laps), ("eval/success_rate", result.laps / max(len(result.rows), 1)),
                               ("eval/cones_per_lap", result.cones_per_lap), ("eval/lap_time_s", result.lap_time_s)):
                logger.record(key, value)
            logger.dump(steps)
        if new:
            self.best = result.score()
            with atomic_path(self.best_dir / "best_model.zip", overwrite=True) as tmp:
                model.save(str(tmp))
            record = {**result.to_dict(), "score": list(result.score())}
            atomic_write_json(self.best_dir / "best_model.json", {**self.meta(steps), "held_out": record},
                              indent=2, overwrite=True)
        return result

    @staticmethod
    def _describe(score: tuple | None) -> str:
        return "none" if score is None else f"{score[0]} laps, {-score[1]} cones"


def ppo_callbacks(total: int, log: Callable[[str], None], selector: Selector | None, eval_freq: int) -> list[Any]:
    """PPO's callbacks: a progress line every rollout (steps, speed, time left, the training episodes'
    laps, cones and reward) and, with a ``selector``, the held-out drives at the start (when no best is
    recorded yet) and every ``eval_freq`` env steps."""
    from stable_baselines3.common.callbacks import BaseCallback

    class ProgressLines(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0, self.steps0 = time.time(), self.model.num_timesteps
            self.ended = self.laps = self.cones = 0

        def _on_step(self) -> bool:
            for done, info in zip(self.locals.get("dones", ()), self.locals.get("infos", ())):
                if done:
                    self.ended += 1
                    self.laps += int(bool(info.get("is_success", False)))
                    self.cones += int(info.get("cones_hit", 0))
            return True

        def _on_rollout_end(self) -> None:
            steps = self.model.num_timesteps
            dt = max(time.time() - self.t0, 1e-9)
            rate = (steps - self.steps0) / dt
            # PPO collects whole rollouts (n_envs x n_steps), so the last one may end past ``total``.
            left = (total - steps) / rate if rate > 0 else float("nan")
            eta = f"about {left / 60:.1f} min left" if steps < total else "the last rollout ended past the target"
            rewards = [e["r"] for e in self.model.ep_info_buffer] if self.model.ep_info_buffer else []
            mean_r = f"{sum(rewards) / len(rewards):.1f}" if rewards else "-"
            episodes = (f"{self.ended} training episodes ended, {self.laps / self.ended:.0%} laps, "
                        f"{self.cones / self.ended:.2f} cones each" if self.ended else "no training episode ended")
            log(f"PPO {steps}/{total} steps ({steps / max(total, 1):.0%}), {rate:.0f} steps/s, "
                f"{dt / 60:.1f} min, {eta}; {episodes}; mean episode reward {mean_r}")
            self.ended = self.laps = self.cones = 0

    class HeldOutSelection(BaseCallback):
        def _on_training_start(self) -> None:
            if selector.best is None:  # type: ignore[union-attr]  # built only with a selector
                selector.evaluate(self.model, self.logger)  # type: ignore[union-attr]  # as above
            self.last = self.model.num_timesteps

        def _on_step(self) -> bool:
            if self.model.num_timesteps - self.last >= eval_freq:
                selector.evaluate(self.model, self.logger)  # type: ignore[union-attr]  # as above
                self.last = self.model.num_timesteps
            return True

    out: list[Any] = [ProgressLines()]
    if selector is not None and eval_freq > 0:
        out.append(HeldOutSelection())
    return out


def echo_to_tty() -> bool:
    """Whether a live progress bar makes sense (stderr is a terminal); log files get the lines only."""
    return sys.stderr.isatty()
