"""``weather-gym evaluate``: run agents through weather presets of rising severity, resumably.

Every cell (agent x track x effect x severity x seed) is one episode; rows go to ``OUT/results.csv``
as cells finish, ``OUT/report.md`` and ``OUT/plots/`` are written at the end. Re-running the same
command skips finished cells and retries failed ones. Everything is validated before a cell runs.

Examples:
    weather-gym evaluate --agent mapper_pure_pursuit --effects droplets,dim --severities 0,1,2,3,4 \\
        --seeds 3 --track small_track --out runs/eval
    weather-gym evaluate --agent gt_pure_pursuit --perception oracle --seeds 1 --max-steps 300 --out runs/smoke
    weather-gym evaluate --agent sb3 --agent-arg path=ppo.zip --perception oracle --out runs/ppo
    weather-gym evaluate ... --backend ray --ray-address auto       # on a running Ray cluster
    weather-gym evaluate --stacks detector,lidar,fused --conditions clear,rain:8mm/h,fog:60m,dusk:20lux \
        --seeds 1 --track peanut --out runs/sensors                    # which sensor carries the stack

The second command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['evaluate', '--agent', 'gt_pure_pursuit', '--perception', 'oracle', '--seeds', '1', '--max-steps', '300', '--out', 'runs/smoke'])
    >>> args.agents, args.perception, args.seeds, args.max_steps
    ('gt_pure_pursuit', 'oracle', 1, 300)
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from functools import partial
from pathlib import Path

from weather_gym.agents import agent_observes
from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._help import literal
from weather_gym.cli._presets_arg import add_presets_arg, default_choice, env_scenario, presets_from_arg
from weather_gym.cli._runner_args import add_runner_args, check_runner_args
from weather_gym.cli.lap import parse_agent_args
from weather_gym.core._option_alias import OneDefaultFormatter, alias
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.lab.evaluation.evaluate import (
    BAGS,
    DEFAULT_PERCEPTION,
    EvalConfig,
    evaluate,
    evaluate_stacks,
    make_cells,
)
from weather_gym.lab.evaluation.report import report_replaceable, write_report
from weather_gym.lab.evaluation.runner import check_results_path
from weather_gym.lab.evaluation.sensors import write_sensor_report
from weather_gym.pipeline.modes import PERCEPTION_MODES, auto_mode, modes_where, perception_mode
from weather_gym.ros.episode_bag import BAG_IMAGES
from weather_gym.tracks import split_track_specs
from weather_gym.weather.presets import ALIASES, CONDITIONS


def _names(text: str) -> tuple[str, ...]:
    return tuple(p.strip() for p in text.split(",") if p.strip())


def _ints(flag: str, text: str) -> tuple[int, ...]:
    out = []
    for part in _names(text):
        try:
            out.append(int(part))
        except ValueError:
            raise InputError(f"{flag}: {part!r} is not an integer (expected a comma-separated list such as 0,1,2)") from None
    return tuple(out)


def _json_arg(flag: str, text: str | None) -> dict:
    if not text:
        return {}
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{flag}: not valid JSON ({exc.msg}): {text!r}") from None
    if not isinstance(value, dict):
        raise InputError(f"{flag}: expected a JSON object such as '{{\"v_max\": 8}}', got {text!r}")
    return value


def register(sub) -> None:
    p = sub.add_parser(
        "evaluate", help="robustness evaluation: agents x effects x severities x seeds x tracks",
        description="Run every cell (agent x track x effect x severity x seed) as one episode, write a tidy "
                    "OUT/results.csv (resumable: finished cells are skipped, failed ones retried), OUT/report.md "
                    "and OUT/plots/*.png. Severities are weather presets (weather_gym/weather/presets.toml).",
        formatter_class=OneDefaultFormatter,
    )
    g = p.add_argument_group("grid")
    g.add_argument("--agent", dest="agents", default="mapper_pure_pursuit",
                   help="agent name(s), comma-separated (weather_gym.agents.AGENTS, or module.path:Factory)")
    alias(g, "--agent", "--agents")
    g.add_argument("--baseline", default=None, metavar="AGENT",
                   help="an agent of --agent the others are compared against in the report, cell by cell "
                        "(lap time ratio, cones hit difference; a table and plots/lap_time_ratio.png)")
    g.add_argument("--effects", default="droplets,dim", help="weather conditions / effect names, comma-separated "
                                                           "(--perception lidar: fog, rain, snow, wet)")
    g.add_argument("--severities", default="0,1,2,3,4", help="preset severities (0-4; the LiDAR's 0-5), comma-separated")
    g.add_argument("--conditions", default=None, metavar="STATES",
                   help="physical weather states, comma-separated (clear, rain:8mm/h, fog:60m, dusk:20lux, "
                        "fog:60m+rain:2mm/h, ...; docs/weather.md): the grid's weathers instead of --effects x "
                        "--severities, reaching camera, LiDAR and tyres")
    g.add_argument("--stacks", default=None, metavar="MODES",
                   help="perception modes to run side by side on the same grid, comma-separated (e.g. "
                        "detector,lidar,fused); adds OUT/sensors.md: which sensor carries the stack per weather")
    seeds = g.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=int, default=3, help="number of seeds: 0..N-1")
    seeds.add_argument("--seed-list", default=None, help="explicit seeds, comma-separated (instead of --seeds)")
    g.add_argument("--track", dest="tracks", default="small_track",
                   help="track names / 'random:SEED' / 'reverse:SPEC' / 'mirror:SPEC' / cone CSV paths, comma-separated")
    alias(g, "--track", "--tracks")
    e = p.add_argument_group("episode")
    e.add_argument("--env-id", default="WeatherGym/ConeTrack-v0", help="Gymnasium id of the scenario")
    e.add_argument("--perception", default=DEFAULT_PERCEPTION, choices=("auto", *PERCEPTION_MODES),
                   help="what the agent sees: auto: the first mode that gives what the agents read (as for lap); " + literal("; ".join(f"{m.name}: {m.describe()}"
                                                                     for m in PERCEPTION_MODES.values())))
    e.add_argument("--laps", type=int, default=1, help="laps per episode")
    e.add_argument("--max-steps", type=int, default=3000, help="step limit per episode (30 steps = 1 s)")
    e.add_argument("--agent-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="keyword for the agent factory, repeatable (e.g. v_max=12, path=model.zip)")
    e.add_argument("--agent-kwargs", default=None, help=argparse.SUPPRESS)  # deprecated: the same as JSON
    e.add_argument("--env-kwargs", default=None, help='JSON object of gymnasium.make arguments, e.g. \'{"camera": {"width": 336, "height": 188}}\'')
    e.add_argument("--perception-kwargs", default=None, help="JSON object of the perception wrapper's arguments (DetectorWrapper / GroundTruthConeWrapper / SurrogatePerceptionWrapper)")
    add_presets_arg(e)
    add_detector_args(e, what=f"for --perception {' / '.join(modes_where(runs_detector=True))}; the same as the "
                               "detector keys of --perception-kwargs")
    r = p.add_argument_group("run")
    r.add_argument("--out", type=Path, required=True, help="output folder (results.csv, report.md, plots/)")
    add_overwrite_arg(r, help="replace a report.md or plots/ in --out that no earlier run of this grid wrote "
                              "(results.csv is always resumed, never replaced)")
    r.add_argument("--bags", action="store_true",
                   help="also write each episode this run drives as an MCAP rosbag2 into OUT/bags/ (docs/ros.md)")
    r.add_argument("--bag-images", choices=BAG_IMAGES, default="jpeg",
                   help="camera frames in the bags: jpeg (CompressedImage) or raw (Image rgb8); default %(default)s")
    add_runner_args(r)
    p.set_defaults(func=_run)


def build_config(args):
    """The ``EvalConfig`` of parsed arguments (validated by ``make_cells`` afterwards)."""

    if args.seed_list is not None:
        seeds = _ints("--seed-list", args.seed_list)
    else:
        if args.seeds < 1:
            raise InputError(f"--seeds must be >= 1, got {args.seeds}")
        seeds = tuple(range(args.seeds))
    return EvalConfig(
        agents=_names(args.agents), effects=_names(args.effects), severities=_ints("--severities", args.severities),
        seeds=seeds, tracks=split_track_specs(args.tracks), env_id=args.env_id, perception=args.perception, laps=args.laps,
        max_steps=args.max_steps, agent_kwargs=_agent_kwargs(args),
        env_kwargs=_json_arg("--env-kwargs", args.env_kwargs),
        perception_kwargs=_perception_kwargs(args),
        presets=_presets(args), conditions=_names(args.conditions) if args.conditions else (),
    )


def _agent_kwargs(args) -> dict:
    """``--agent-arg KEY=VALUE`` options, and the deprecated ``--agent-kwargs JSON`` (with a note)."""
    given = parse_agent_args(args.agent_arg)
    if args.agent_kwargs is not None:
        print("note: --agent-kwargs is deprecated and goes in the next release; use --agent-arg KEY=VALUE "
              "(repeatable)", file=sys.stderr)
        old = _json_arg("--agent-kwargs", args.agent_kwargs) or {}
        if clash := sorted(set(old) & set(given)):
            raise InputError(f"{', '.join(clash)} given both with --agent-arg and in --agent-kwargs; give each once")
        given = {**old, **given}
    return given


def _preset_cells(args) -> list[tuple[str, int]]:
    """The ``(condition, severity)`` cells of the grid that read presets (effect names that are not conditions do not)."""
    conds = [e for e in _names(args.effects) if e in CONDITIONS or e in ALIASES]
    return [(c, s) for c in conds for s in _ints("--severities", args.severities)]


def _presets(args) -> str | dict[str, str] | None:
    """``--presets``: a file (pool, FILE) for every track, or with ``resolved`` one per track, resolved for it."""
    mode = None if args.perception == "auto" else perception_mode(args.perception)
    choice = default_choice(args.presets, _preset_cells(args), mode)
    if choice != "resolved":
        path = presets_from_arg(choice, None)
        return None if path is None else str(path)
    detector = detector_spec_from_args(args) if perception_mode(args.perception).runs_detector else None
    env_kwargs = _json_arg("--env-kwargs", args.env_kwargs)
    return {t: str(presets_from_arg("resolved", partial(env_scenario, args.env_id, t, detector, env_kwargs),
                                    progress=not args.no_progress))
            for t in split_track_specs(args.tracks)}


def _perception_kwargs(args) -> dict:
    """``--perception-kwargs`` plus the ``--detector*`` options (as the DetectorWrapper's keywords)."""
    kw = _json_arg("--perception-kwargs", args.perception_kwargs) or {}
    given = {"detector": args.detector, "detector_classes": args.detector_classes,
             "detector_resize": args.detector_resize, "detector_input": args.detector_input,
             "score_threshold": args.detector_threshold}
    given = {k: v for k, v in given.items() if v is not None}
    if given and not perception_mode(args.perception).runs_detector and getattr(args, "stacks", None):
        given = {}  # --stacks: the detector options go to the stacks that run the detector
    if given and not perception_mode(args.perception).runs_detector:
        raise InputError(f"--detector options go with --perception {' / '.join(modes_where(runs_detector=True))}, "
                         f"not {args.perception}")
    clash = sorted(set(given) & set(kw))
    if clash:
        raise InputError(f"{', '.join(clash)} given both as --detector options and in --perception-kwargs; give each once")
    if given:
        detector_spec_from_args(args)  # a bad spec or a missing file fails here, before any cell runs
    return {**kw, **given}


def resolve_auto_perception(args) -> None:
    """``--perception auto``: the mode ``lap`` would take, the same for every agent of the grid."""
    if args.perception != "auto":
        return
    modes = {a: auto_mode(agent_observes(a)).name for a in _names(args.agents)}
    if len(set(modes.values())) > 1:
        raise InputError("--perception auto gives the agents different modes ("
                         + ", ".join(f"{a}: {m}" for a, m in modes.items()) + "); name one with --perception")
    args.perception = next(iter(modes.values()), DEFAULT_PERCEPTION)


def _run_stacks(args) -> int:
    """``--stacks``: one grid per perception mode, one results file, the per-sensor report."""
    stacks = _names(args.stacks)
    for m in stacks:
        perception_mode(m)
    if len(set(stacks)) != len(stacks):
        raise InputError(f"--stacks repeats a mode: {args.stacks}")
    configs = []
    for m in stacks:
        args.perception = m
        configs.append(build_config(args))
    cells = [c for config in configs for c in make_cells(config)]  # every stack's grid checked first
    check_results_path(args.out / "results.csv")
    command = shlex.join(["weather-gym", *sys.argv[1:]]) if "evaluate" in sys.argv[1:2] else None
    print(f"{len(cells)} cells ({', '.join(stacks)}) -> {args.out / 'results.csv'} ({args.backend}, "
          f"{args.workers} workers)", file=sys.stderr)
    replace = report_replaceable(args.out, overwrite=args.overwrite)
    started = time.perf_counter()
    rows = evaluate_stacks(configs, args.out, workers=args.workers, backend=args.backend,
                           ray_address=args.ray_address, progress=not args.no_progress,
                           retry_failed=not args.skip_failed)
    write_report(rows, args.out, config=configs[0], wall_s=time.perf_counter() - started, command=command,
                 group_by=("agent", "perception", "track", "effect", "severity"), plot_metrics=(),
                 overwrite=replace)
    path = write_sensor_report(rows, args.out, command=command, overwrite=replace)
    failed = [r for r in rows if r["status"] != "ok"]
    print(f"{len(rows) - len(failed)} ok, {len(failed)} failed; report: {args.out / 'report.md'}, {path}")
    for r in failed[:5]:
        print(f"  failed: {r['perception']} {r['track']} {r['effect']} seed {r['seed']}: {r['error']}", file=sys.stderr)
    return 1 if failed else 0


def _run(args) -> int:
    check_runner_args(args)
    if args.stacks:
        return _run_stacks(args)
    resolve_auto_perception(args)
    config = build_config(args)
    if args.baseline is not None and args.baseline not in config.agents:
        raise InputError(f"--baseline {args.baseline!r} must be one of the agents of --agent "
                         f"({', '.join(config.agents)}): its cells are what the others are compared with")
    cells = make_cells(config)  # every name and number checked before anything runs
    check_results_path(args.out / "results.csv")
    command = shlex.join(["weather-gym", *sys.argv[1:]]) if "evaluate" in sys.argv[1:2] else None
    print(f"{len(cells)} cells -> {args.out / 'results.csv'} ({args.backend}, {args.workers} workers)", file=sys.stderr)
    replace = report_replaceable(args.out, overwrite=args.overwrite)  # someone else's report: refused now
    started = time.perf_counter()
    rows = evaluate(config, args.out, workers=args.workers, backend=args.backend, ray_address=args.ray_address,
                    progress=not args.no_progress, retry_failed=not args.skip_failed, bags=args.bags,
                    bag_images=args.bag_images)
    write_report(rows, args.out, config=config, wall_s=time.perf_counter() - started, command=command,
                 baseline=args.baseline, overwrite=replace)
    failed = [r for r in rows if r["status"] != "ok"]
    print(f"{len(rows) - len(failed)} ok, {len(failed)} failed; report: {args.out / 'report.md'}")
    if args.bags:
        bags = args.out / BAGS
        n = sum(1 for p in bags.iterdir() if not p.name.startswith(".")) if bags.is_dir() else 0
        print(f"bags: {bags} ({n} episode bag(s), MCAP rosbag2; cells resumed from results.csv were not driven "
              "again and write none)")
    for r in failed[:5]:
        print(f"  failed: {r['agent']} {r['track']} {r['effect']}@{r['severity']} seed {r['seed']}: {r['error']}",
              file=sys.stderr)
    if len(failed) > 5:
        print(f"  ... and {len(failed) - 5} more (see the report)", file=sys.stderr)
    return 1 if failed else 0
