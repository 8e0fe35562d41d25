"""Docs snippets run as pasted: a ``make_vec_env`` (async, forkserver workers that import the script)
sits under ``if __name__ == "__main__":`` in every Python block of the README and docs, and a script
that leaves the guard out still runs (its workers start with fork, with a warning). Every ``python``
block of the README and the docs runs as it is pasted, in a fresh process in an empty folder, unless
an HTML comment ``<!-- fragment: WHY -->`` on the line before marks it as a fragment (a signature, a
line inside a larger program): a fragment must say why and still parse. Every relative link of the
README, the changelog and the docs leads to a file that exists."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RECIPES = ROOT / "docs" / "extending.md"


def _python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), flags=re.S)


def _doc_blocks() -> list[tuple[str, int, str, str | None]]:
    """``(page, index, code, why)`` for every python block of the README and docs; ``why`` is the
    reason of a ``<!-- fragment: WHY -->`` marker on the line before the block (None: it must run)."""
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for i, m in enumerate(re.finditer(r"(?:<!--\s*fragment:?(.*?)-->\s*\n)?```python\n(.*?)```", text, flags=re.S)):
            why = None if m.group(1) is None else m.group(1).strip()
            out.append((str(path.relative_to(ROOT)), i, m.group(2), why))
    return out


DOC_BLOCKS = _doc_blocks()


def _unguarded_vec_calls(source: str) -> list[int]:
    from weather_gym.pipeline.builder import _is_main_guard

    tree = ast.parse(source)
    out = []
    for node in tree.body:
        if _is_main_guard(node):
            continue
        out += [n.lineno for n in ast.walk(node) if isinstance(n, ast.Call)
                and getattr(n.func, "attr", getattr(n.func, "id", None)) == "make_vec_env"]
    return out


def test_every_make_vec_env_snippet_is_under_the_main_guard():
    found = 0
    for path in DOCS:
        for block in _python_blocks(path):
            if "make_vec_env(" not in block:
                continue
            found += 1
            assert not _unguarded_vec_calls(block), f"{path.name}: make_vec_env outside __main__ guard:\n{block}"
    assert found >= 2  # the README's and docs/envs.md's quick starts


@pytest.mark.slow
def test_an_unguarded_script_falls_back_to_fork_with_a_warning(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text("import weather_gym\n"
                      "venv = weather_gym.make_vec_env(num_envs=2, perception='gt_cones', max_episode_steps=5)\n"
                      "obs, info = venv.reset(seed=0)\n"
                      "print('cones', obs['cones'].shape)\n"
                      "venv.close()\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "cones (2, 64, 14)" in done.stdout
    assert f"{script}:2, outside `if __name__ == \"__main__\":`" in done.stderr and "with fork instead" in done.stderr


@pytest.mark.slow
@pytest.mark.parametrize("page, index, code", [(p, i, c) for p, i, c, why in DOC_BLOCKS if why is None],
                         ids=[f"{p}#{i}" for p, i, _, why in DOC_BLOCKS if why is None])
def test_every_python_block_of_the_docs_runs_as_pasted(page, index, code, tmp_path):
    script = tmp_path / f"block_{index}.py"
    script.write_text(code, encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          env=env)
    assert done.returncode == 0, f"{page} python block {index} (mark it <!-- fragment: WHY --> if it is one):\n" \
                                 f"{done.stderr[-2000:]}"


def test_fragments_say_why_and_parse():
    fragments = [(p, i, c, why) for p, i, c, why in DOC_BLOCKS if why is not None]
    for page, index, code, why in fragments:
        assert why, f"{page} python block {index}: a fragment marker must say why (<!-- fragment: WHY -->)"
        ast.parse(code, filename=f"{page} python block {index}")
    assert len(fragments) < len(DOC_BLOCKS) / 2  # most blocks run


HELP_AFTER_RECIPES = """
import sys
from weather_gym.cli import build_parser, main

commands = [name for action in build_parser()._subparsers._group_actions for name in action.choices]
failed = []
for command in commands:
    try:
        main([command, "--help"])
    except SystemExit as exc:
        if exc.code != 0:
            failed.append(f"{command}: exit {exc.code}")
    except Exception as exc:
        failed.append(f"{command}: {type(exc).__name__}: {exc}")
print("commands", len(commands), file=sys.stderr)
assert not failed, failed
"""


@pytest.mark.slow
def test_every_command_help_works_after_the_recipes_registered_their_entries(tmp_path):
    # the recipes' entries (a mode described with "5 %", a metric, an agent, an effect) reach the
    # help texts of the commands that list their registry: argparse formats those with %
    script = tmp_path / "recipes_then_help.py"
    script.write_text("\n\n".join(_python_blocks(RECIPES)) + HELP_AFTER_RECIPES, encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert int(re.search(r"commands (\d+)", done.stderr).group(1)) >= 10


def test_every_relative_link_in_the_docs_resolves():
    pages = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]
    broken = []
    for page in pages:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            path = target.split("#", 1)[0]
            if path and not re.match(r"[a-z]+:", path) and not (page.parent / path).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, "links to missing files:\n" + "\n".join(broken)
