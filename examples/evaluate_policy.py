"""Put a saved stable-baselines3 policy through the robustness evaluation, per weather severity.

Reads the model's JSON sidecar (``model.json`` beside ``model.zip``, ``ppo_<N>_steps.json`` beside a
checkpoint, ``best_model.json`` beside ``best/best_model.zip``: ``weather-gym train`` writes one beside
every model it saves; for a model without one, the run folder's ``model.json`` one or two folders up)
for the env id and camera it was trained with, then runs the same harness
as ``weather-gym evaluate`` with the ``sb3`` agent: ``OUT/results.csv`` (resumable),
``OUT/report.md``, ``OUT/plots/``. The perception defaults to ``detector``: a policy trained on
ground-truth cone lists (``gt_cones``) drives on the detector's cone list of the weathered frame,
the same observation space.

Usage:
    python examples/evaluate_policy.py --model runs/ppo_cones/model.zip --effects droplets,dim \\
        --severities 0,1,2,3,4 --seeds 3 --track small_track --out runs/ppo_eval
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from weather_gym.agents.sb3 import model_sidecar
from weather_gym.cli import run_command
from weather_gym.core.errors import FileFormatError, MissingInputError
from weather_gym.lab.evaluation.evaluate import EvalConfig, evaluate
from weather_gym.lab.evaluation.report import report_replaceable, write_report


def find_sidecar(model: Path) -> Path:
    """The JSON that records the env ``model`` was trained on: beside it, else the run folder's ``model.json``
    (``best/`` and ``checkpoints/`` sit one folder below the run)."""
    sidecar = model_sidecar(model)
    if sidecar is not None:
        return sidecar
    raise MissingInputError(f"{model.with_suffix('.json')} not found (nor a model.json in its run folder): it "
                            "records the env the model was trained on (weather-gym train writes it)")


def config_for_model(model: Path, *, effects, severities, seeds, tracks=None, max_steps: int = 3000,
                     laps: int = 1, perception: str = "detector") -> EvalConfig:
    """The ``EvalConfig`` evaluating ``model`` on the observation it was trained on (from its sidecar)."""
    model = model if model.suffix == ".zip" else model.with_suffix(".zip")
    if not model.is_file():
        raise MissingInputError(f"model {model} not found")
    sidecar = find_sidecar(model)
    try:
        meta = json.loads(sidecar.read_text())
        meta["track"], meta["env_id"]  # noqa: B018 - the keys the config needs
    except (ValueError, KeyError, TypeError) as exc:
        raise FileFormatError(f"{sidecar}: not a model sidecar written by examples/train_ppo.py ({exc})") from None
    return EvalConfig(
        agents=("sb3",), agent_kwargs={"path": str(model.resolve()), "algo": meta.get("algo", "PPO")},
        effects=tuple(effects), severities=tuple(severities), seeds=tuple(seeds),
        tracks=tuple(tracks or (meta["track"],)), env_id=meta["env_id"], perception=perception,
        env_kwargs=meta.get("env_kwargs", {}), max_steps=max_steps, laps=laps,
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--model", type=Path, required=True,
                   help="model zip from weather-gym train: model.zip, best/best_model.zip or any checkpoint")
    p.add_argument("--effects", default="droplets,dim")
    p.add_argument("--severities", default="0,1,2,3,4")
    p.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1")
    p.add_argument("--tracks", default=None, help="comma-separated (default: the training track)")
    p.add_argument("--max-steps", type=int, default=3000)
    p.add_argument("--perception", default="detector",
                   help="what the policy sees: detector (default; the weathered frame's detections) or oracle")
    p.add_argument("--laps", type=int, default=1)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    p.add_argument("--backend", choices=("process", "ray", "serial"), default="process")
    p.add_argument("--overwrite", action="store_true", help="replace a report in --out that no earlier run wrote")
    return run_command(_evaluate, p.parse_args(argv))


def _evaluate(args) -> int:
    config = config_for_model(
        args.model, effects=[e for e in args.effects.split(",") if e],
        severities=[int(s) for s in args.severities.split(",") if s], seeds=range(args.seeds),
        tracks=[t for t in args.tracks.split(",") if t] if args.tracks else None,
        max_steps=args.max_steps, laps=args.laps, perception=args.perception)
    replace = report_replaceable(args.out, overwrite=args.overwrite)  # refuse someone else's report before running
    rows = evaluate(config, args.out, workers=args.workers, backend=args.backend)
    write_report(rows, args.out, config=config, overwrite=replace)
    failed = sum(r["status"] != "ok" for r in rows)
    print(f"{len(rows) - failed} ok, {failed} failed; report: {args.out / 'report.md'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
