"""What a PPO run writes besides SB3's own logs: model metadata beside every saved model (final,
checkpoint, best), the newest checkpoint for ``--resume``, and the learning and warm-start curves
(PNG, read from the CSV logs SB3's logger writes).

Example:
    >>> import tempfile, zipfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> for n in (64, 256, 128):
    ...     zipfile.ZipFile(folder / f"ppo_{n}_steps.zip", "w").close()
    ...     _ = (folder / f"ppo_{n}_steps.json").write_text("{}")
    >>> latest_checkpoint(folder).name
    'ppo_256_steps.zip'
    >>> _ = (folder / "ppo_256_steps.zip").write_bytes(b"PK cut short by a stop")
    >>> latest_checkpoint(folder).name
    'ppo_128_steps.zip'
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import zipfile
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib import pyplot as plt

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_path, atomic_write_json


def _metadata_callbacks(meta, checkpoints: Path, checkpoint_freq: int, best: Path):
    """SB3's ``CheckpointCallback`` writing each checkpoint atomically, then ``ppo_<N>_steps.json`` beside it
    (so a checkpoint with its ``.json`` is complete), and the callback ``EvalCallback`` calls on a new best
    model, which writes ``best/best_model.zip`` and ``best/best_model.json`` the same way (give
    ``EvalCallback`` no ``best_model_save_path``). A stop or a crash mid-write leaves the previous files."""
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class CheckpointWithMetadata(CheckpointCallback):
        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq == 0:
                zip_path = Path(self._checkpoint_path(extension="zip"))
                with atomic_path(zip_path, overwrite=True) as tmp:
                    self.model.save(str(tmp))
                stats = self.model.get_vec_normalize_env()
                if self.save_vecnormalize and stats is not None:
                    with atomic_path(self._checkpoint_path("vecnormalize_", extension="pkl"), overwrite=True) as tmp:
                        stats.save(str(tmp))
                atomic_write_json(zip_path.with_suffix(".json"), meta(self.num_timesteps), indent=2, overwrite=True)
            return True

    class BestModel(BaseCallback):
        def _on_step(self) -> bool:
            with atomic_path(best / "best_model.zip", overwrite=True) as tmp:
                self.model.save(str(tmp))
            atomic_write_json(best / "best_model.json", meta(self.num_timesteps), indent=2, overwrite=True)
            return True

    return (CheckpointWithMetadata(checkpoint_freq, str(checkpoints), name_prefix="ppo", save_vecnormalize=True),
            BestModel())


def _checkpoint_steps(path: Path | None) -> int:
    m = re.fullmatch(r"ppo_(\d+)_steps\.zip", path.name) if path is not None else None
    return int(m.group(1)) if m else 0


def latest_checkpoint(folder: Path) -> Path | None:
    """The complete checkpoint with the most steps in ``folder`` (``ppo_<steps>_steps.zip``), or None.

    Complete: a whole zip file with its ``.json`` beside it (written after the model and its
    normalisation statistics), so one cut short by a stop (Ctrl-C, SIGTERM, kill -9) is passed over."""
    found = sorted(folder.glob("ppo_*_steps.zip"), key=_checkpoint_steps)
    for path in reversed(found):
        if path.with_suffix(".json").is_file() and zipfile.is_zipfile(path):
            return path
    return None


def plot_learning_curve(out: Path) -> Path | None:
    """``out/learning_curve.png`` from every segment's ``progress.csv``: training and held-out reward,
    held-out lap completion."""
    matplotlib.use("Agg")
    rows: list[dict[str, str]] = []
    for f in sorted((out / "logs").glob("*/progress.csv")):
        with f.open(newline="") as fh:
            rows += list(csv.DictReader(fh))
    if not rows:
        return None

    def series(key: str) -> tuple[np.ndarray, np.ndarray]:
        pts = sorted((float(r["time/total_timesteps"]), float(r[key])) for r in rows
                     if r.get(key) not in (None, "") and r.get("time/total_timesteps") not in (None, ""))
        return (np.array([p[0] for p in pts]), np.array([p[1] for p in pts])) if pts else (np.zeros(0), np.zeros(0))

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for key, label in (("rollout/ep_rew_mean", "training tracks (mean of the last 100 episodes)"),
                       ("eval/mean_reward", "held-out track (EvalCallback)")):
        x, y = series(key)
        if len(x):
            ax1.plot(x, y, marker="." if key.startswith("eval") else None, label=label)
    ax1.set_xlabel("environment steps")
    ax1.set_ylabel("episode reward (m of progress, penalties)")
    if ax1.lines:
        ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    x, y = series("eval/success_rate")
    if len(x):
        ax2.plot(x, y, marker=".", color="tab:green")
    ax2.set_xlabel("environment steps")
    ax2.set_ylabel("held-out drives that were laps")
    ax2.set_ylim(-0.05, 1.05)
    ax2.grid(alpha=0.3)
    fig.suptitle(f"PPO on the cone list ({out.name})")
    fig.tight_layout()
    return save_figure(fig, out / "learning_curve.png", overwrite=True, dpi=110)


def plot_pretrain_curve(out: Path, record: dict[str, Any] | None) -> Path | None:
    """``out/pretrain_curve.png`` from a warm start's record (``run.json["pretrain"]``): the behaviour-cloning
    loss before and after each DAgger round's fit, and per round the share of the steps the expert drove and
    the share of ended episodes that were laps."""
    rounds = (record or {}).get("rounds_log") or []
    if not rounds:
        return None
    matplotlib.use("Agg")
    r = np.array([x["round"] for x in rounds])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.semilogy(r, [x["loss_before"] for x in rounds], "o--", label="before the round's fit (new data included)")
    ax1.semilogy(r, [x["loss"] for x in rounds], "o-", label="after the fit")
    ax1.set_xlabel("DAgger round")
    ax1.set_ylabel("BC loss (MSE of the policy mean to the expert's action)")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(r, [x["expert_share"] for x in rounds], "o-", label="steps driven by the expert")
    ax2.plot(r, [x["laps"] / max(x["episodes"], 1) for x in rounds], "o-", label="ended episodes that were laps")
    ax2.set_xlabel("DAgger round")
    ax2.set_ylim(-0.05, 1.05)
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    fig.suptitle(f"warm start: behaviour cloning of {(record or {}).get('expert')} with DAgger ({out.name})")
    fig.tight_layout()
    return save_figure(fig, out / "pretrain_curve.png", overwrite=True, dpi=110)


def model_metadata(settings: dict[str, Any], hp: dict[str, Any], seed: int, eval_track: str,
                   timesteps: int, pretrain: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON written beside every saved model (final, checkpoint, best): the env it was trained on
    (and, after ``--pretrain``, the warm start's record: expert, steps, rounds, BC loss per round)."""
    extra = {"pretrain": pretrain} if pretrain is not None else {}
    return {**extra, "algo": "PPO", "timesteps": int(timesteps), "n_envs": hp["n_envs"], "seed": seed,
            "env_id": settings["env_id"], "track": eval_track, "train_tracks": settings["tracks"],
            "perception": settings["perception"], "train_noise": settings["noise"],
            "env_kwargs": settings["env_kwargs"], "train_weather": settings["weather"],
            "train_max_steps": settings["max_steps"], "policy": hp["policy"],
            "features": "weather_gym.agents.sb3_features.ConeListExtractor",
            "cone_memory": settings.get("cone_memory", False)}


RUN_FILES = ("model.zip", "model.json", "run.json", "train.log", "learning_curve.png", "pretrain_curve.png",
             "checkpoints/ppo_*_steps.zip", "checkpoints/ppo_*_steps.json", "checkpoints/ppo_vecnormalize_*_steps.pkl",
             "best/best_model.zip", "best/best_model.json", "logs/steps[0-9]*")
"""What a run writes in its folder, as glob patterns (a ``logs/steps<N>`` folder is one segment's SB3 logs:
``progress.csv``, TensorBoard events, ``evaluations.npz``). The one list ``--overwrite`` removes (then the
folders ``checkpoints``, ``best`` and ``logs`` if that left them empty); nothing else in the folder is touched."""
TRAIN_LOG = "train.log"
"""The run's log: every progress line and statistic the run printed, with the time (appended by each segment)."""
RUN_RECORD = "run.json"
"""The file that makes a folder a run: ``--resume`` continues it, ``--overwrite`` replaces it."""


def holds_run(out: Path) -> bool:
    """Whether ``out`` holds a weather-gym training run (its ``run.json`` has settings and segments)."""
    try:
        run = json.loads((out / RUN_RECORD).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(run, dict) and "settings" in run and isinstance(run.get("segments"), list)


def _remove_run(out: Path) -> list[Path]:
    """Remove what a run wrote in ``out`` (:data:`RUN_FILES`); the paths removed."""
    gone = []
    temporary = [f"{folder}/.{name}.*.tmp*".lstrip("/") for folder, _, name in (p.rpartition("/") for p in RUN_FILES)
                 if not name.startswith("steps")]  # a write cut short by kill -9 (weather_gym.core._io's names)
    for pattern in (*RUN_FILES, *temporary):
        for path in sorted(out.glob(pattern)):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
            gone.append(path)
    for name in ("checkpoints", "best", "logs"):
        folder = out / name
        if folder.is_dir() and not folder.is_symlink() and not any(folder.iterdir()):
            folder.rmdir()
    return gone
