"""Teacher-student warm start of ``weather-gym train``: behaviour cloning with DAgger before PPO.

A registered agent (the *expert*, e.g. ``gt_pure_pursuit``, which reads the true pose from the step
info) labels every observation of the training envs with its action; the PPO policy's Gaussian mean
is fitted to those labels (mean squared error). Round 0 drives with the expert; each later round
``r`` drives with the student (its deterministic action) except for a share ``beta**r`` of the
steps, where the expert's action is taken, and records the expert's action for every observation
the student saw (DAgger: the student learns to recover from its own mistakes). All rounds' data is
kept, and the student is fitted on it after each round. Afterwards the policy's log std is set to
``log_std`` so that PPO's exploration does not wreck the cloned driver.

Everything random (episode seeds, the driver mixture, minibatch order) comes from generators
derived from the run's seed: the same seed gives the same policy.

Example:
    >>> cfg = PretrainConfig(expert="gt_pure_pursuit", steps=600, rounds=2, epochs=2)
    >>> cfg.steps_per_round()
    [300, 300]
    >>> PretrainConfig(expert="gt_pure_pursuit", steps=-1)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: --pretrain-steps must be an integer >= 1, got -1
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any

import gymnasium as gym
import numpy as np
from pydantic import AfterValidator
from tqdm.auto import tqdm

from weather_gym.agents import AGENTS, make_agent
from weather_gym.core.errors import InputError
from weather_gym.core.schema import NonNegative, Positive, PositiveInt, Share, check_fields, option

__all__ = ["PretrainConfig", "bc_loss", "collect", "policy_mean", "pretrain"]

_SEED_KEY = (0xBC0,)  # the pretraining's own streams, apart from PPO's and the envs' for the same seed
_EVAL_CHUNK = 4096


def _known_agent(name: str) -> str:
    AGENTS.get(name)  # InputError naming the valid agents
    return name


@dataclass(frozen=True)
class PretrainConfig:
    """Settings of the warm start (``weather-gym train --pretrain EXPERT ...``).

    Attributes:
        expert: a registered agent name (``weather_gym.agents.AGENTS``) that labels the observations.
        steps: env steps of expert-labelled data in all rounds together.
        rounds: DAgger rounds (round 0 drives with the expert, later ones mostly with the student).
        epochs: passes over the aggregated data after each round.
        beta: share of expert-driven steps in round ``r`` is ``beta**r``.
        batch_size, learning_rate: Adam minibatches of the fit.
        log_std: the policy's log std after pretraining (PPO's exploration noise from there).
        teacher_narrow_width: the expert slows where the track is narrower than this (m; 0: off;
            ``gt_pure_pursuit``'s ``narrow_width``, passed to the expert only when above 0).
    """

    expert: Annotated[str, AfterValidator(_known_agent), option("--pretrain")]
    steps: Annotated[PositiveInt, option("--pretrain-steps")] = 60_000
    rounds: Annotated[PositiveInt, option("--dagger-rounds")] = 4
    epochs: Annotated[PositiveInt, option("--pretrain-epochs")] = 20
    beta: Annotated[Share, option("--dagger-beta")] = 0.5
    batch_size: PositiveInt = 256
    learning_rate: Positive = 1e-3
    log_std: Annotated[float, option("--pretrain-log-std")] = -1.6
    teacher_narrow_width: Annotated[NonNegative, option("--teacher-narrow-width")] = 0.0

    def __post_init__(self) -> None:
        check_fields(self, by_option=True)  # each field against its annotation, named by its option
        if self.steps < self.rounds:
            raise InputError(f"--pretrain-steps {self.steps} is fewer than one step per DAgger round "
                             f"(--dagger-rounds {self.rounds})")

    def steps_per_round(self) -> list[int]:
        """Env steps of each round (the remainder goes to the first rounds)."""
        q, r = divmod(self.steps, self.rounds)
        return [q + (i < r) for i in range(self.rounds)]


# ------------------------------------------------------------------ policy helpers
def policy_mean(policy: Any, obs: dict[str, np.ndarray]) -> Any:
    """The Gaussian mean of an SB3 actor-critic ``policy`` for a batch of dict observations (a tensor)."""
    return policy.get_distribution(policy.obs_to_tensor(obs)[0]).distribution.mean


def bc_loss(policy: Any, data: dict[str, Any]) -> float:
    """Mean squared error between ``policy``'s mean action and the expert's ``data["action"]``."""
    import torch

    n = len(data["action"])
    total = 0.0
    with torch.no_grad():
        for i in range(0, n, _EVAL_CHUNK):
            obs = {k: v[i:i + _EVAL_CHUNK] for k, v in data["obs"].items()}
            mean = policy_mean(policy, obs)
            target = torch.as_tensor(data["action"][i:i + _EVAL_CHUNK], device=mean.device)
            total += float(((mean - target) ** 2).sum())
    return total / (n * data["action"].shape[1])


def _stack(obs_list: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.stack([o[k] for o in obs_list]) for k in obs_list[0]}


# ------------------------------------------------------------------ data
def collect(envs: list[gym.Env], experts: list[Any], policy: Any | None, steps: int, beta: float,
            rng: np.random.Generator, bar: Any = None) -> tuple[dict[str, Any], dict[str, float]]:
    """``steps`` env steps (over all ``envs``, in lockstep) labelled with the expert's action.

    Each env is reset (seed from ``rng``) and its expert reset with the reset info. A step is driven
    by the expert with probability ``beta``, else by ``policy``'s deterministic action (``policy``
    None: always the expert). Returns ``({"obs": {key: array}, "action": (N, 2) float32}, stats)``.
    """
    import torch

    n = len(envs)
    obs_rows: list[dict[str, np.ndarray]] = []
    labels: list[np.ndarray] = []
    stats: dict[str, float] = {"episodes": 0, "laps": 0, "expert_steps": 0}
    cur_obs: list[Any] = []
    cur_info: list[dict] = []
    for env, expert in zip(envs, experts):
        seed = int(rng.integers(2**31 - 1))
        o, info = env.reset(seed=seed)
        expert.reset(seed, info)
        cur_obs.append(o)
        cur_info.append(info)
    done = 0
    while done < steps:
        active = min(n, steps - done)
        expert_actions = [np.asarray(experts[i].act(cur_obs[i], cur_info[i]), np.float32).reshape(-1)
                          for i in range(active)]
        use_expert = rng.uniform(size=active) < beta if policy is not None else np.ones(active, bool)
        driven = [a.copy() for a in expert_actions]
        if policy is not None and not use_expert.all():
            with torch.no_grad():
                mean = policy_mean(policy, _stack(cur_obs[:active])).cpu().numpy()
            for i in np.flatnonzero(~use_expert):
                driven[i] = np.clip(mean[i], -1.0, 1.0).astype(np.float32)
        for i in range(active):  # type: ignore[assignment]  # i: numpy ints above, ints here
            obs_rows.append({k: np.array(v) for k, v in cur_obs[i].items()})  # never a reused buffer
            labels.append(np.clip(expert_actions[i], -1.0, 1.0))
            o, _, terminated, truncated, info = envs[i].step(driven[i])
            if terminated or truncated:
                stats["episodes"] += 1
                stats["laps"] += int(bool(info.get("is_success", info.get("lap", 0) >= 1)))
                seed = int(rng.integers(2**31 - 1))
                o, info = envs[i].reset(seed=seed)
                experts[i].reset(seed, info)
            cur_obs[i], cur_info[i] = o, info
        stats["expert_steps"] += int(use_expert.sum())
        done += active
        if bar is not None:
            bar.update(active)
    return {"obs": _stack(obs_rows), "action": np.asarray(labels, np.float32)}, stats


class _Ticker:
    """A tqdm bar (on a terminal) that also logs a line every ``every_s`` seconds (for log files)."""

    def __init__(self, bar: Any, log: Callable[[str], None], what: str, total: int, every_s: float = 60.0) -> None:
        self.bar, self.log, self.what, self.total, self.every_s = bar, log, what, total, every_s
        self.done, self.t0 = 0, time.time()
        self.next = self.t0 + every_s

    def update(self, n: int) -> None:
        self.bar.update(n)
        self.done += n
        now = time.time()
        if now >= self.next and self.done < self.total:
            self.next = now + self.every_s
            rate = self.done / max(now - self.t0, 1e-9)
            self.log(f"{self.what}: {self.done}/{self.total} steps, {rate:.0f} steps/s, "
                     f"about {(self.total - self.done) / max(rate, 1e-9) / 60:.1f} min left in this round")


def _concat(parts: list[dict[str, Any]]) -> dict[str, Any]:
    return {"obs": {k: np.concatenate([p["obs"][k] for p in parts]) for k in parts[0]["obs"]},
            "action": np.concatenate([p["action"] for p in parts])}


def _fit(policy: Any, optimizer: Any, data: dict[str, Any], epochs: int, batch_size: int,
         rng: np.random.Generator) -> None:
    import torch

    n = len(data["action"])
    policy.train()
    for _ in range(epochs):
        order = rng.permutation(n)
        for i in range(0, n, batch_size):
            idx = order[i:i + batch_size]
            mean = policy_mean(policy, {k: v[idx] for k, v in data["obs"].items()})
            loss = torch.nn.functional.mse_loss(mean, torch.as_tensor(data["action"][idx], device=mean.device))
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.train(False)


def _actor_parameters(policy: Any) -> list[Any]:
    seen: dict[int, Any] = {}
    for module in (policy.pi_features_extractor, policy.mlp_extractor.policy_net, policy.action_net):
        for p in module.parameters():
            seen.setdefault(id(p), p)
    return list(seen.values())


def pretrain(policy: Any, envs: list[gym.Env], config: PretrainConfig, seed: int,
             progress: bool = True, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Fit ``policy`` (an SB3 actor-critic policy) to ``config.expert`` on ``envs`` with DAgger.

    Returns the record written to ``run.json`` and ``model.json``: the settings, per round the
    samples, expert-driven share, episodes and laps driven, and the BC loss on all data so far before
    and after the fit, the initial loss and the wall time.
    """
    import torch

    started = time.time()
    ss = np.random.SeedSequence(seed, spawn_key=_SEED_KEY)
    drive_rng, fit_rng = (np.random.default_rng(s) for s in ss.spawn(2))
    teacher = {"narrow_width": config.teacher_narrow_width} if config.teacher_narrow_width > 0 else {}
    experts = [make_agent(config.expert, env.unwrapped.track, env.unwrapped.config.camera, **teacher)  # type: ignore[attr-defined]  # ConeTrackEnvs
               for env in envs]
    optimizer = torch.optim.Adam(_actor_parameters(policy), lr=config.learning_rate)
    parts: list[dict[str, Any]] = []
    rounds: list[dict[str, Any]] = []
    policy.train(False)
    for r, n_steps in enumerate(config.steps_per_round()):
        beta = 1.0 if r == 0 else float(config.beta) ** r
        with tqdm(total=n_steps, desc=f"BC round {r}", unit="step", dynamic_ncols=True, disable=not progress) as bar:
            ticker = _Ticker(bar, log, f"pretrain round {r + 1} of {config.rounds}", n_steps)
            part, stats = collect(envs, experts, None if r == 0 else policy, n_steps, beta, drive_rng, ticker)
        parts.append(part)
        data = _concat(parts)
        before = bc_loss(policy, data)
        _fit(policy, optimizer, data, config.epochs, config.batch_size, fit_rng)
        after = bc_loss(policy, data)
        rounds.append({"round": r, "steps": n_steps, "samples": len(data["action"]),
                       "expert_share": round(stats["expert_steps"] / max(n_steps, 1), 4),
                       "episodes": stats["episodes"], "laps": stats["laps"],
                       "loss_before": round(before, 6), "loss": round(after, 6)})
        log(f"pretrain round {r + 1} of {config.rounds}: {n_steps} steps ({rounds[-1]['expert_share']:.0%} expert-driven, "
              f"{stats['episodes']} episodes ended, {stats['laps']} laps), {len(data['action'])} samples, "
              f"BC loss {before:.4f} -> {after:.4f}, {time.time() - started:.0f} s so far")
    with torch.no_grad():
        policy.log_std.fill_(float(config.log_std))
    return {**dataclasses.asdict(config), "rounds_log": rounds, "initial_loss": rounds[0]["loss_before"],
            "final_loss": rounds[-1]["loss"], "wall_s": round(time.time() - started, 1)}
