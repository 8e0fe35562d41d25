"""``weather-gym gap``: the files it writes, the report schema, repeatability and user errors."""

from __future__ import annotations

import json
import tomllib

import pytest

from weather_gym.cli import main

pytestmark = pytest.mark.slow

HIDDEN = [{"name": "vignette", "k": 0.5}]
STEP_KEYS = {"added", "gap_before", "gap_after", "evidence"}
DISAGREEMENT_KEYS = {"signal", "sim", "measured", "effect_size", "significant"}


def _run(measured, out, cache, *extra):
    return main(["gap", str(measured), "--out", str(out), "--seed", "1", "--quiet", "--fit-frames", "12",
                 "--cache", str(cache), *extra])


@pytest.fixture(scope="module")
def cli_run(make_measured, gap_cache, tmp_path_factory):
    measured = make_measured("cli_vignette", HIDDEN)
    root = tmp_path_factory.mktemp("gap_cli")
    model = root / "model.toml"
    model.write_text("# the clean simulator\neffects = []\n")
    assert _run(measured, root / "a", gap_cache, "--model", str(model)) == 0
    return measured, model, root


def test_writes_report_model_markdown_and_plots(cli_run, capsys):
    measured, model, root = cli_run
    out = root / "a"
    report = json.loads((out / "report.json").read_text())
    for key in ("mode", "disagreements", "steps", "missing_effects", "gap_before", "gap_after", "model",
                "perception_gap_before", "perception_gap_after"):
        assert key in report
    assert report["mode"] == "paired" and report["missing_effects"] == ["vignette"]
    assert report["model"] == str(out / "model.toml")
    assert all(DISAGREEMENT_KEYS <= set(d) for d in report["disagreements"])
    step = report["steps"][0]
    assert STEP_KEYS <= set(step) and {"name", "params"} <= set(step["added"])
    assert step["added"]["params"]["k"] == pytest.approx(0.5, abs=0.05)
    with open(out / "model.toml", "rb") as f:
        assert [e["name"] for e in tomllib.load(f)["effects"]] == ["vignette"]
    md = (out / "report.md").read_text()
    assert md.index("## Perception gap") < md.index("## Image-signal gap")  # perception first
    for png in ("gap_before_after.png", "disagreements.png", "perception.png", "screening_step1.png", "frames.png"):
        assert (out / png).stat().st_size > 1000 and png in report["plots"] and png in md


def test_same_seed_same_report(cli_run, gap_cache):
    measured, model, root = cli_run
    assert _run(measured, root / "b", gap_cache, "--model", str(model)) == 0

    def strip(path):
        r = json.loads(path.read_text())
        r.pop("timings")
        r.pop("model")
        return r

    assert strip(root / "a" / "report.json") == strip(root / "b" / "report.json")
    assert (root / "a" / "model.toml").read_text() == (root / "b" / "model.toml").read_text()


def test_existing_report_is_not_overwritten(cli_run, gap_cache, capsys):
    measured, model, root = cli_run
    before = (root / "a" / "report.json").read_text()
    assert _run(measured, root / "a", gap_cache, "--model", str(model)) == 2
    assert "already exists" in capsys.readouterr().err
    assert (root / "a" / "report.json").read_text() == before


@pytest.mark.parametrize("text, message", [
    ('[[effects]]\nname = "snow"\nk = 0.5\n', "expected one of"),
    ('[[effects]]\nname = "dim"\n', "needs 'k'"),
    ('[[effects]]\nname = "dim"\nk = 1.5\n', "outside [0.0, 1.0]"),
    ('[[effects]]\nname = "dim"\nk = 0.2\nsharpness = 3\n', "unknown parameter"),
    ("effects = [\n", "not valid TOML"),
    ('weather = "dim"\n', "unknown top-level key"),
])
def test_bad_model_file_is_a_clear_error(cli_run, gap_cache, tmp_path, capsys, text, message):
    measured, _, _ = cli_run
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    assert _run(measured, tmp_path / "out", gap_cache, "--model", str(bad)) == 2
    err = capsys.readouterr().err
    assert message in err and str(bad) in err
    assert not (tmp_path / "out" / "report.json").exists()


def test_missing_inputs_are_clear_errors(tmp_path, capsys):
    assert main(["gap", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
