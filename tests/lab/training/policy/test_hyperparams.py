"""The hyper-parameter schema (``weather_gym.lab.training.policy.hyperparams.Hyperparams``): every key of the file and every
option of ``weather-gym train`` typed and range-checked, errors naming file, key, value and range; no
import of a named policy; the declared defaults are PPO's."""

from __future__ import annotations

import dataclasses
import inspect
import re
import sys

import pytest

from weather_gym.cli import main
from weather_gym.core.errors import FileFormatError, InputError, LimitError
from weather_gym.lab.training.policy.hyperparams import (
    MAX_N_ENVS,
    NOT_IN_FILE,
    POLICIES,
    PPO_DEFAULTS,
    Bound,
    Hyperparams,
    LinearSchedule,
    load_hyperparams,
    ppo_arguments,
)
from weather_gym.lab.training.policy.train import DEFAULT_HYPERPARAMS_KEY, _check_n_envs

KEY = DEFAULT_HYPERPARAMS_KEY


def _file(tmp_path, *lines: str):
    path = tmp_path / "hp.yml"
    path.write_text(f"{KEY}:\n  n_timesteps: 1000\n" + "".join(f"  {line}\n" for line in lines))
    return path


@pytest.mark.parametrize(("line", "error", "expected"), [
    ('n_steps: "many"', InputError, r"n_steps must be an integer in \[1, 1048576\], got 'many'"),
    ("batch_size: 0", LimitError, r"batch_size must be an integer in \[2, 1048576\] \(PPO normalises .*\), got 0"),
    ("learning_rate: -1", LimitError, r"learning_rate must be a number in \(0, 1\] or 'lin_<that>'.*, got -1"),
    ("learning_rate: lin_-3e-4", LimitError, r"learning_rate must be .*, got 'lin_-3e-4'"),
    ("learning_rate: lin_fast", InputError, r"learning_rate must be .*, got 'lin_fast'"),
    ("gamma: 5", LimitError, r"gamma must be a number in \(0, 1\], got 5"),
    ("gamma: .nan", LimitError, r"gamma must be a number in \(0, 1\], got nan"),
    ("gae_lambda: 1.5", LimitError, r"gae_lambda must be a number in \[0, 1\], got 1.5"),
    ("clip_range: 0", LimitError, r"clip_range must be a number in \(0, 1\]"),
    ("ent_coef: -0.1", LimitError, r"ent_coef must be a number in \[0, 1\], got -0.1"),
    ("n_epochs: 0", LimitError, r"n_epochs must be an integer in \[1, 1000\], got 0"),
    ("n_epochs: true", InputError, r"n_epochs must be an integer in \[1, 1000\], got True"),
    ("n_envs: 100000", LimitError, rf"n_envs must be an integer in \[1, {MAX_N_ENVS}\], got 100000"),
    ("normalize_advantage: 1", InputError, r"normalize_advantage must be true or false, got 1"),
    ("target_kl: 0", LimitError, r"target_kl must be a number in \(0, 1\] or null, got 0"),
    ("policy: os.system", InputError, r"policy must be one of \[.*ConeListPolicy', 'MultiInputPolicy'\], got 'os.system'"),
    ('normalize: "dict(clip_obs=-1)"', LimitError, r"normalize clip_obs must be a number > 0, got -1"),
    ('normalize: "dict(norm_obs=1, x=2)"', InputError, r"normalize: unknown keyword\(s\) \['x'\]"),
    ('normalize: "[1]"', InputError, r"normalize must be true, false or a dict of VecNormalize keywords"),
    ('policy_kwargs: "dict(net_arch=[0])"', LimitError, r"policy_kwargs net_arch must be a list of layer widths"),
    ('policy_kwargs: "dict(log_std_init=50)"', LimitError, r"policy_kwargs log_std_init must be a number in \[-10, 2\]"),
    ('policy_kwargs: "dict(features_extractor_class=1)"', InputError, r"unknown keyword\(s\) \['features_extractor_class'\]"),
    ('policy_kwargs: "dict(net_arch=[1] * 10**9)"', InputError, "only literals and dict"),
    ("n_steps: 64\n  batch_size: 48", LimitError, r"batch_size \(48\) must divide the rollout n_steps \* n_envs = "
                                                   r"64 \* 1 = 64 .*e\.g\. 2, 4, 8, 16, 32, 64"),
    ("n_steps: 64\n  batch_size: 128", LimitError, r"batch_size \(128\) must divide the rollout"),
    ("n_steps: 1", LimitError, r"n_steps: the rollout n_steps \* n_envs = 1 \* 1 must be at least 2"),
    ("n_envs: 64\n  n_steps: 65536", LimitError, r"n_steps: the rollout .* = 4194304 must be at most 1048576"),
])
def test_every_key_is_typed_and_range_checked_naming_file_key_value_and_range(tmp_path, line, error, expected):
    path = _file(tmp_path, line)
    with pytest.raises(error, match=expected) as info:
        load_hyperparams(path, KEY)
    assert str(info.value).startswith(f"{path} [{KEY}]")  # the file and its section, then the key


@pytest.mark.parametrize("key", sorted(NOT_IN_FILE))
def test_seed_verbose_device_are_refused_and_not_offered(tmp_path, key):
    with pytest.raises(FileFormatError, match=rf"'{key}' is not read from a hyper-parameter file: "):
        load_hyperparams(_file(tmp_path, f"{key}: 1"), KEY)
    with pytest.raises(FileFormatError, match=r"unknown key\(s\) \['n_stepz'\]") as info:
        load_hyperparams(_file(tmp_path, "n_stepz: 1"), KEY)
    assert f"'{key}'" not in str(info.value)  # the valid keys listed are the ones read
    assert key not in Hyperparams.keys()


def test_a_named_policy_is_never_imported(tmp_path, monkeypatch):
    """A module named by ``policy`` would run its top-level code on import: it is refused from a list first."""
    marker = tmp_path / "imported"
    (tmp_path / "wg_probe_policy.py").write_text(f"open({str(marker)!r}, 'w').close()\nclass P: pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for name in ("wg_probe_policy.P", "this.x", "os.system"):
        before = set(sys.modules)
        with pytest.raises(InputError, match="policy must be one of"):
            load_hyperparams(_file(tmp_path, f"policy: {name}"), KEY)
        assert not marker.exists() and set(sys.modules) == before
    assert "wg_probe_policy" not in sys.modules and "this" not in sys.modules


def test_a_file_that_is_not_utf8_is_a_typed_error(tmp_path):
    path = tmp_path / "latin1.yml"
    path.write_bytes(f"{KEY}:\n  n_timesteps: 1000\n  # caf\xe9\n".encode("latin-1"))
    with pytest.raises(FileFormatError, match=rf"{path}: not UTF-8 text \(byte \d+\)"):
        load_hyperparams(path, KEY)


def test_rl_zoo3_linear_schedules_become_ppo_schedules(tmp_path):
    hp = load_hyperparams(_file(tmp_path, "learning_rate: lin_3e-4", "clip_range: lin_0.2", "n_steps: 64",
                                "batch_size: 32"), KEY)
    assert hp["ppo"]["learning_rate"] == "lin_3e-4"  # as written (run.json, model.json)
    kwargs = ppo_arguments(hp)
    assert kwargs["learning_rate"] == LinearSchedule(3e-4) and kwargs["clip_range"] == LinearSchedule(0.2)
    assert kwargs["learning_rate"](1.0) == pytest.approx(3e-4) and kwargs["learning_rate"](0.25) == pytest.approx(7.5e-5)


def test_the_declared_defaults_and_keys_are_ppos():
    from stable_baselines3 import PPO

    params = inspect.signature(PPO.__init__).parameters
    assert {k: params[k].default for k in PPO_DEFAULTS} == PPO_DEFAULTS
    assert set(Hyperparams.ppo_keys()) == set(PPO_DEFAULTS) and set(PPO_DEFAULTS) <= set(params)
    assert set(NOT_IN_FILE) <= set(params)  # PPO's keywords the file may not set (the CLI sets them)
    for f in dataclasses.fields(Hyperparams):
        if f.name in PPO_DEFAULTS and PPO_DEFAULTS[f.name] is not None:  # every default lies in its declared range
            f.metadata["bound"].check(PPO_DEFAULTS[f.name], f.name)


def test_bound_messages_say_the_range():
    assert Bound(float, 0, 1, lo_open=True).expected() == "a number in (0, 1]"
    assert Bound(int, 1).expected() == "an integer >= 1"
    assert Bound(bool).expected() == "true or false"
    assert Bound(int, 1, 3).check(2.0, "x") == 2  # YAML's !!float 2e0
    with pytest.raises(LimitError, match=r"^x must be a finite number, got inf$"):
        Bound(float).check(float("inf"), "x")


def test_subproc_starts_at_most_4_processes_per_core_as_make_vec_env():
    from weather_gym.pipeline import MAX_SYNC_ENVS

    assert MAX_N_ENVS == MAX_SYNC_ENVS
    _check_n_envs(64, "dummy", cpus=2)
    _check_n_envs(64, "split", cpus=2)
    _check_n_envs(8, "subproc", cpus=2)
    with pytest.raises(LimitError, match=r"n_envs 9 with --vec subproc would start 9 processes: at most 8 \(4 per CPU"):
        _check_n_envs(9, "subproc", cpus=2)
    assert POLICIES[0] == "weather_gym.agents.sb3_features.ConeListPolicy"


@pytest.mark.parametrize(("argv", "expected"), [
    (["--batch-size", "1"], r"--batch-size must be an integer in \[2, 1048576\] \(PPO normalises the advantage "
                            r"over each mini-batch\), got 1"),
    (["--batch-size", "100"], r"--batch-size \(100\) must divide the rollout n_steps \* n_envs = 256 \* 16 = 4096"),
    (["--n-envs", "100000"], rf"--n-envs must be an integer in \[1, {MAX_N_ENVS}\], got 100000"),
    (["--gamma", "5"], r"--gamma must be a number in \(0, 1\], got 5.0"),
    (["--learning-rate", "0"], r"--learning-rate must be a number in \(0, 1\]"),
    (["--ent-coef", "-1"], r"--ent-coef must be a number in \[0, 1\]"),
    (["--n-epochs", "0"], r"--n-epochs must be an integer in \[1, 1000\]"),
    (["--n-steps", "1", "--n-envs", "1"], r"--n-steps: the rollout n_steps \* n_envs = 1 \* 1 must be at least 2"),
    (["--timesteps", "0", "--pretrain", "none"], r"--timesteps must be an integer >= 1 \(0 only with --pretrain\)"),
    (["--timesteps", str(10**10)], r"--timesteps must be an integer in \[1, 1000000000\] or null"),
    (["--log-std-init", "50"], r"--log-std-init must be a number in \[-10, 2\], got 50.0"),
    (["--max-steps", "0"], r"--max-steps must be an integer in \[1, 1000000\], got 0"),
    (["--eval-episodes", "0"], r"--eval-episodes must be an integer in \[1, 1000\]"),
    (["--torch-threads", "1000"], r"--torch-threads must be an integer in \[1, 256\]"),
    (["--vec", "subproc", "--n-envs", "9"], r"n_envs 9 with --vec subproc would start 9 processes: at most 8"),
    (["--noise", "[1]"], r"--noise must be a JSON object of fields, got \[1\]"),
    (["--init", "nosuch.zip"], r"--init nosuch.zip: no such model file"),
    (["--init", __file__], r"--init .*test_hyperparams.py: not a saved SB3 model"),
    (["--camera", "9999x10"], r"--camera 9999x10: each side must be at most 4096 pixels"),
    (["--eval-max-steps", "0"], r"--eval-max-steps must be an integer in \[1, 1000000\], got 0"),
    (["--eval-weathers", ""], r"--eval-weathers must be a list of at least 1 strings, got \(\)"),
    (["--eval-track", "small_track,hairpin"], r"--eval-track hairpin is also a training track"),
    (["--track", "peanut,random:1,width=2.5", "--eval-track", "random:1,width=2.5"],  # one spec, arguments and all
     r"--eval-track random:1,width=2.5 is also a training track"),
    (["--detection-range", "-3"], r"--detection-range must be a distance in metres > 0 or 'none', got '-3'"),
])
def test_every_option_is_checked_before_anything_is_written(tmp_path, capsys, monkeypatch, argv, expected):
    monkeypatch.setattr("weather_gym.lab.training.policy.train.os.cpu_count", lambda: 2)
    out = tmp_path / "run"
    assert main(["train", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert re.search(expected, err), err
    assert not out.exists()


def test_rl_md_quotes_the_code():
    """docs/rl.md's table of keys, its OracleNoise default and its PPO set-up come from the code."""
    import json
    from pathlib import Path

    from weather_gym.lab.training.policy import HYPERPARAMS
    from weather_gym.lab.training.policy.run_outputs import RUN_FILES
    from weather_gym.lab.training.policy.train import DEFAULT_NOISE, build_parser

    text = (Path(__file__).resolve().parents[4] / "docs" / "rl.md").read_text()
    rows = dict(re.findall(r"^\| `(\w+)` \| [^|]*\| (.+?) \|$", text, flags=re.M))
    for f in dataclasses.fields(Hyperparams):
        bound = f.metadata.get("bound")
        if bound is not None and bound.kind is not dict:
            assert rows.get(f.name) == bound.expected(), f.name
            assert bound.option is None or f"| `{f.name}` | `{bound.option}` |" in text
    assert set(rows) >= set(Hyperparams.keys())
    quoted = re.search(r"`OracleNoise` \(`--noise`, default `(\{.*?\})`", text, flags=re.S).group(1)
    assert json.loads(quoted.replace("\n", " ")) == DEFAULT_NOISE
    hp = load_hyperparams(HYPERPARAMS, KEY)
    setup = re.search(r"\* \*\*PPO\*\*: (\d+) envs x (\d+) steps per update, batch (\d+), (\d+) epochs, learning rate "
                      r"(\S+), gamma (\S+),", text).groups()
    assert [int(v) for v in setup[:4]] == [hp["n_envs"], hp["ppo"]["n_steps"], hp["ppo"]["batch_size"],
                                           hp["ppo"]["n_epochs"]]
    assert [float(v) for v in setup[4:]] == [hp["ppo"]["learning_rate"], hp["ppo"]["gamma"]]
    assert f"`--log-std-init {hp['policy_kwargs']['log_std_init']}`" in text
    d = build_parser().parse_args(["--out", "x"])
    assert f"every {d.eval_freq:,} steps (`--eval-freq`)" in text and f"lap or {d.max_steps} steps" in text
    assert f"{d.eval_episodes} episode each (`--eval-episodes`" in text and f"{d.eval_max_steps} steps (`--eval-max" in text
    assert d.eval_track == "small_track,mirror:hairpin,mirror:peanut"
    assert "`small_track`, `mirror:hairpin` and `mirror:peanut`" in text
    assert f"`--timesteps` ({hp['n_timesteps']:,})" in text and f"`--eval-freq` ({d.eval_freq:,})" in text
    assert f"(default {d.pretrain_steps:,})" in text and f"rounds (default {d.dagger_rounds})" in text
    assert f"(default {d.dagger_beta})" in text and f"default {d.pretrain_epochs})" in text
    assert f"`--pretrain-log-std` (default {d.pretrain_log_std}" in text
    assert f"`--teacher-narrow-width M` (default\n{d.teacher_narrow_width}: off)" in text
    for pattern in RUN_FILES:  # the list --overwrite removes, as the page names it
        assert pattern.split("/")[-1].split("_*")[0].replace("[0-9]*", "<N>") in text, pattern


def test_a_missing_or_huge_file_is_a_typed_error(tmp_path):
    from weather_gym.core.errors import MissingInputError
    from weather_gym.lab.training.policy.hyperparams import MAX_FILE_BYTES

    with pytest.raises(MissingInputError, match="hyper-parameter file .*nope.yml not found"):
        load_hyperparams(tmp_path / "nope.yml", KEY)
    big = _file(tmp_path, "# " + "x" * MAX_FILE_BYTES)
    with pytest.raises(FileFormatError, match=rf"{big}: \d+ bytes; a hyper-parameter file has at most {MAX_FILE_BYTES}"):
        load_hyperparams(big, KEY)
