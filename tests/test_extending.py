"""docs/extending.md followed literally: an effect, a perception mode and a metric added as it says work end
to end, with the number of files it names.

The effect goes into a copy of the package (its file from the page's python block, its registry line from
the page's diff block), and nothing else is edited; the mode and the metric are the page's blocks
registered in-process (as a user's script does). One subprocess then checks what the page promises: the
effect in weather specs, presets (its generated nominal rows), the gap workflow's chain order and
``weather-gym degrade``; every command's ``--help`` renders with the mode's ``%`` in its description.
"""

from __future__ import annotations

import filecmp
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "extending.md"


def _section(text: str, title: str) -> str:
    start = text.index(f"\n## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else None]


def _blocks(section: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", section, flags=re.S)


def _table_row(text: str, anchor: str) -> tuple[int, list[str]]:
    """``(count, paths)`` of the guide's table row whose first cell links to ``#anchor``."""
    row = next(line for line in text.splitlines() if line.startswith("| [") and f"](#{anchor})" in line)
    files = row.split("|")[2]
    count = int(re.match(r"\s*(\d+):", files).group(1))
    return count, re.findall(r"`([^`]+)`", files)


def _apply_diff(path: Path, diff: str) -> None:
    """Apply a one-hunk diff block (context ' ', removed '-', added '+') to ``path``; the context must
    occur exactly once."""
    lines = [line for line in diff.splitlines() if line and line[0] in " -+"]
    old = "\n".join(line[1:] for line in lines if line[0] in " -") + "\n"
    new = "\n".join(line[1:] for line in lines if line[0] in " +") + "\n"
    text = path.read_text(encoding="utf-8")
    assert text.count(old) == 1, f"the guide's diff does not match {path} exactly once:\n{old}"
    path.write_text(text.replace(old, new), encoding="utf-8")


def _changed_files(a: Path, b: Path) -> list[str]:
    """Files added or changed in tree ``b`` against tree ``a`` (paths relative to their parent)."""
    out: list[str] = []

    def walk(cmp: filecmp.dircmp, rel: str) -> None:
        out.extend(f"{rel}/{n}" for n in cmp.right_only + cmp.diff_files)
        for name, sub in cmp.subdirs.items():
            walk(sub, f"{rel}/{name}")

    walk(filecmp.dircmp(a, b, ignore=["__pycache__"]), a.name)
    return sorted(out)


CHECK = r'''
import contextlib, io, sys, tomllib
from pathlib import Path

import cv2
import numpy as np

import weather_gym
assert weather_gym.__file__.startswith(sys.argv[1]), weather_gym.__file__
from weather_gym.cli import build_parser, main
from weather_gym.lab.gap.weather_model import chain_order, insert_position, read_model
from weather_gym.weather import EFFECTS, make, parse_weather, to_spec
from weather_gym.weather.presets import conditions, load_presets, preset_entry, preset_spec

# the effect: registry, weather specs, presets, the gap chain
assert "flicker" in EFFECTS.names()
assert to_spec(parse_weather("flicker:0.5"))[0]["k"] == 0.5
assert parse_weather({"flicker": {"k": 0.3, "depth": 0.5}}) == make("flicker", k=0.3, depth=0.5)
Path("model.toml").write_text('[[effects]]\nname = "dim"\nk = 0.4\n\n[[effects]]\nname = "flicker"\nk = 0.6\n')
assert [e.name for e in read_model("model.toml")] == ["dim", "flicker"]
assert "flicker" in conditions() and "flicker" in load_presets()["presets"]
assert preset_spec("flicker", 2) == [{"name": "flicker", "k": 0.5}]
entry = preset_entry("flicker", 3)
assert entry["calibrated"] is False and entry["description"] == "Nominal heavy flicker", entry
assert to_spec(parse_weather("flicker@4"))[0]["k"] == 1.0
order = chain_order()
assert order.index("dim") < order.index("flicker") < order.index("exposure"), order
assert insert_position([make("dim", k=0.5), make("noise", k=0.2)], "flicker") == 1

# the effect on the command line
frame = np.full((48, 64, 3), 180, np.uint8)
cv2.imwrite("in.png", frame)
assert main(["degrade", "in.png", "out.png", "--weather", "flicker@4", "--seed", "3"]) in (0, None)
out = cv2.imread("out.png")
assert out.shape == frame.shape and int(out.max()) < 180, int(out.max())

# the mode and the metric, registered as the page's blocks do
for code in sys.argv[2:]:
    exec(compile(Path(code).read_text(), code, "exec"), {"__name__": "__main__"})
from weather_gym.lab.evaluation.metrics import METRICS
from weather_gym.pipeline.modes import PERCEPTION_MODES
assert "noisy_cones" in PERCEPTION_MODES and "laps_per_minute" in METRICS

# every command's --help renders (registry text with a % included)
commands = [name for action in build_parser()._subparsers._group_actions for name in action.choices]
texts = {}
for command in commands:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        try:
            main([command, "--help"])
        except SystemExit as exc:
            assert exc.code == 0, (command, exc.code)
    texts[command] = buf.getvalue()
assert "5 % range noise" in " ".join(texts["evaluate"].split()), texts["evaluate"]
assert len(commands) >= 10
print("ok", len(commands))
'''


def test_following_the_guide_adds_an_effect_a_mode_and_a_metric(tmp_path):
    guide = GUIDE.read_text(encoding="utf-8")
    # the effect: exactly the files the table names, as the section says
    count, named = _table_row(guide, "a-weather-effect")
    effect = _section(guide, "A weather effect")
    (file_block,) = _blocks(effect, "python")
    (diff_block,) = _blocks(effect, "diff")
    new_file, edited = (p.replace("<name>", "flicker") for p in named)
    copy = tmp_path / "weather_gym"
    shutil.copytree(ROOT / "weather_gym", copy, ignore=shutil.ignore_patterns("__pycache__"))
    for data in ("envs", "tracks"):  # the checkout's data folders, beside the package as in a checkout
        (tmp_path / data).symlink_to(ROOT / data)
    (tmp_path / new_file).write_text(file_block, encoding="utf-8")
    _apply_diff(tmp_path / edited, diff_block)
    changed = _changed_files(ROOT / "weather_gym", copy)
    assert changed == sorted([new_file, edited]) and len(changed) == count == 2, changed
    # the mode and the metric: one entry each, in the one file the table names
    blocks = []
    for anchor, title, registers in (("a-perception-mode", "A perception mode", "register_mode(PerceptionMode("),
                                     ("a-metric", "A metric", "register_metric(Metric(")):
        count, named = _table_row(guide, anchor)
        assert count == len(named) == 1 and (ROOT / named[0]).is_file(), (anchor, named)
        (block,) = _blocks(_section(guide, title), "python")
        assert block.count(registers) == 1, anchor
        entry = block[:block.index("\n\n", block.index(registers))]  # up to the entry; not the demo after it
        blocks.append(tmp_path / f"{anchor}.py")
        blocks[-1].write_text(entry, encoding="utf-8")
    script = tmp_path / "check.py"
    script.write_text(CHECK, encoding="utf-8")
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "WEATHER_GYM_PRESETS"}  # the shipped presets
    env["PYTHONPATH"] = str(tmp_path)  # the copy, not the checkout
    done = subprocess.run([sys.executable, str(script), str(copy), *map(str, blocks)], capture_output=True,
                          text=True, timeout=600, cwd=work, env=env)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    assert re.search(r"^ok \d+$", done.stdout, flags=re.M), done.stdout
