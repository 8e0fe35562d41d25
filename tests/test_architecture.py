"""The layers contract of docs/architecture.md, checked on every import of every module.

Every ``import`` statement of the package is read from its source (those inside functions and
methods too), so an upward dependency cannot hide in a function body. Three rules:

1. no import runs up a floor: a layer imports only the rows below it in pyproject.toml's import-linter contract;
2. the heavy packages are imported only where the table allows them (``HEAVY``): PyBullet in the
   simulator, onnxruntime in perception, torch/onnx in training and the SB3 feature extractor, Ray in
   the evaluation runner;
3. everything else is imported at module level: an import inside a function is only for those heavy,
   optional packages (or a module of ours that imports one of them at module level), or an optional
   dependency guarded by ``try: import x`` / ``except ImportError`` (PyYAML, PyAV, fcntl);
4. no import cycle: the module-level imports among our modules (those under ``if TYPE_CHECKING:`` left
   out) form no strongly connected component of more than one module;
5. no arrow up a layer: the layers, joined by every import between them (inside functions too), form
   no cycle, so the layers have one order and every import runs down it.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "weather_gym"

PYPROJECT = PACKAGE.parent / "pyproject.toml"
_CONTRACT = next(c for c in tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"]
                 if c["type"] == "layers")
ROWS: list[list[str]] = [[name.strip() for name in row.split("|")] for row in reversed(_CONTRACT["layers"])]
"""The layers, bottom row first, as ``pyproject.toml``'s import-linter contract lists them (one place)."""
RANK = {name: i for i, row in enumerate(ROWS) for name in row}
"""Layer (a folder under ``weather_gym/``, ``lab.gap`` for one inside the lab) -> its row."""

HEAVY: dict[str, set[str]] = {
    "pybullet": {"sim"},
    "pybullet_data": {"sim"},
    "onnxruntime": {"perception", "lab.bench"},
    "torch": {"lab.training", "agents", "lab.bench"},
    "onnx": {"lab.training"},
    "ray": {"lab.evaluation", "cli"},
    "stable_baselines3": {"agents", "lab.training"},
    "numba": {"sim", "surrogate", "tracks", "weather"},
}
"""Heavy package -> the layers that may import it. ``lab.bench`` compares against a torch baseline;
``agents`` holds the SB3 feature extractor (a torch module); ``numba`` compiles the geometric ground
truth (``sim.visibility``), the car's dynamics (``sim.car``), one point's centerline projection
(``tracks._kernel``, imported by ``Track`` on first use, so that loading a track does not load numba), the
refractive drops' blend, the sensor noise's pass and the motion smear's blend (``weather._drop_blend``,
``weather._noise_pass``, ``weather._near_blend``, each imported with the first frame that needs it, so that
loading the weather layer does not load numba) and the surrogate's per-step draws (``surrogate.sample``,
``surrogate.point``'s crowding) and stays out of the other layers (its import takes about a second, a
compile seconds on a cold cache)."""

NEVER_IMPORTED_BY: dict[str, set[str]] = {"gymnasium": {"core", "tracks", "camera", "sim", "weather", "lidar_weather"}}


def _modules() -> dict[str, Path]:
    out = {}
    for f in sorted(PACKAGE.rglob("*.py")):
        name = ".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = f
    return out


MODULES = _modules()


def layer_of(module: str) -> str | None:
    """The layer of a ``weather_gym`` module: the deepest folder on its path that the rows name
    (``None`` for anything else; ``"root"`` for the package itself, the lab's own ``__init__`` and the
    deprecated aliases in ``_moved/``, which belong to no layer)."""
    parts = module.split(".")
    if parts[0] != "weather_gym":
        return None
    for n in range(len(parts), 1, -1):
        name = ".".join(parts[1:n])
        if name in RANK:
            return name
    return "root"


def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    names = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return any(isinstance(n, ast.Name) and n.id in ("ImportError", "ModuleNotFoundError") for n in names)


def _imports(module: str, path: Path) -> list[tuple[str, int, bool]]:
    """(imported module, line, inside a function?) for every import statement of ``module``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    inside: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            inside.update(id(n) for n in ast.walk(node) if n is not node)
    for node in ast.walk(tree):  # optional dependencies: `try: import x` / `except ImportError: fallback`
        if isinstance(node, ast.Try) and any(_catches_import_error(h) for h in node.handlers):
            for stmt in node.body:
                if isinstance(stmt, (ast.Import, ast.ImportFrom)):
                    inside.discard(id(stmt))
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_pkg else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # `from pkg import sub` imports the submodule (and runs pkg/__init__, counted when it
            # binds anything but submodules)
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES]
            names = subs + ([target] if len(subs) < len(node.names) else [])
        else:
            continue
        out += [(n, node.lineno, id(node) in inside) for n in names]
    return out


def _module_level_heavy() -> set[str]:
    """Our modules that import a heavy package at module level, directly or through another of ours."""
    direct = {m: [t for t, _, fn in _imports(m, p) if not fn] for m, p in MODULES.items()}
    heavy: set[str] = set()
    changed = True
    while changed:
        changed = False
        for m, targets in direct.items():
            if m not in heavy and any(t.split(".")[0] in HEAVY or t in heavy for t in targets):
                heavy.add(m)
                changed = True
    return heavy


HEAVY_MODULES = _module_level_heavy()
IMPORTS = {m: _imports(m, p) for m, p in MODULES.items()}


def test_the_scan_sees_imports_inside_functions(tmp_path):
    src = tmp_path / "probe.py"
    src.write_text("import numpy\n"
                   "def f():\n    from weather_gym.envs import cone_track\n"
                   "def g():\n    try:\n        import yaml\n    except ImportError:\n        pass\n")
    found = {(t, fn) for t, _, fn in _imports("weather_gym.weather.probe", src)}
    assert ("numpy", False) in found
    assert ("weather_gym.envs.cone_track", True) in found          # hidden upward import: seen
    assert ("yaml", False) in found                                # optional dependency: allowed
    assert layer_of("weather_gym.sim.world") == "sim"
    assert layer_of("weather_gym.lab.training.detector.train") == "lab.training"
    assert layer_of("weather_gym.core.errors") == "core"
    assert layer_of("weather_gym._moved.errors") == "root"
    assert layer_of("numpy") is None


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_import_runs_up_a_floor(module):
    """A layer imports only rows below its own: not a row above, not a neighbour in its own row."""
    src = layer_of(module)
    bad = []
    for target, line, _ in IMPORTS[module]:
        dst = layer_of(target)
        if dst is None or dst == src or src == "root":
            continue
        if dst == "root":
            bad.append((line, target, "the package root, the lab's __init__ and the deprecated aliases are imported by no layer"))
        elif RANK[dst] >= RANK[src]:
            bad.append((line, target, f"{dst!r} is not below {src!r} in the rows of pyproject.toml"))
    assert not bad, f"{module}: " + "; ".join(f"line {ln}: imports {t} ({why})" for ln, t, why in bad)


def test_every_folder_is_a_layer():
    """The floor plan is the table: every folder of the package (but the lab wing's and the layers' own
    sub-folders) is a row of the contract, and every row is a folder."""
    folders = {".".join(p.relative_to(PACKAGE).parts) for p in PACKAGE.rglob("*") if p.is_dir()
               and p.name not in ("__pycache__", "models") and not p.name.startswith("_")}
    top = {f for f in folders if "." not in f or f.startswith("lab.") and f.count(".") == 1}
    assert top - {"lab"} == set(RANK) - {"lab"}, (sorted(top - set(RANK)), sorted(set(RANK) - top))
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert loose == [], f"modules loose at the package's top: {loose}"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_heavy_packages_only_where_allowed(module):
    src = layer_of(module)
    bad = []
    for target, line, _ in IMPORTS[module]:
        top = target.split(".")[0]
        if top in HEAVY and src not in HEAVY[top]:
            bad.append(f"line {line}: {target} (allowed in {sorted(HEAVY[top])})")
        if src in NEVER_IMPORTED_BY.get(top, set()):
            bad.append(f"line {line}: {target} (never in layer {src!r})")
    assert not bad, f"{module} ({src}): " + "; ".join(bad)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_are_at_module_level_except_heavy_optional_ones(module):
    bad = [f"line {line}: {target}" for target, line, in_function in IMPORTS[module]
           if in_function and target.split(".")[0] not in HEAVY and target not in HEAVY_MODULES]
    assert not bad, f"{module}: imports inside functions (move them to the top): " + "; ".join(bad)


def test_weather_never_touches_the_simulator():
    for module, imports in IMPORTS.items():
        if layer_of(module) == "weather":
            assert not [t for t, _, _ in imports if t.split(".")[0] == "pybullet" or layer_of(t) in ("sim", "envs")]


def test_training_a_detector_does_not_need_the_simulator():
    """Reading COCO sets and training run where PyBullet is not installed (a GPU box, say)."""
    import subprocess
    import sys

    probe = ("import sys\n"
             "class NoSim:\n"
             "    def find_spec(self, name, path=None, target=None):\n"
             "        if name.split('.')[0] in ('pybullet', 'pybullet_data'):\n"
             "            raise ImportError(name)\n"
             "sys.meta_path.insert(0, NoSim())\n"
             "import weather_gym.lab.training.detector.train, weather_gym.lab.datasets.coco\n")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]


# ---------------------------------------------------------------------------------- cycles (rules 4, 5)
def _type_checking_lines(path: Path) -> set[int]:
    """Lines of the import statements under ``if TYPE_CHECKING:`` (annotations only: never run)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    lines: set[int] = set()
    for node in ast.walk(tree):
        test = getattr(node, "test", None)
        if isinstance(node, ast.If) and ((isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
                                         or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")):
            lines.update(n.lineno for stmt in node.body for n in ast.walk(stmt)
                         if isinstance(n, (ast.Import, ast.ImportFrom)))
    return lines


def module_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of ``modules`` it imports when it is imported (module level, not under
    ``if TYPE_CHECKING:``)."""
    graph = {}
    for m, path in modules.items():
        skip = _type_checking_lines(path)
        graph[m] = {t for t, line, in_function in _imports(m, path)
                    if not in_function and line not in skip and t in modules and t != m}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm, iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def test_the_cycle_finder_finds_a_planted_cycle(tmp_path):
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set(), "c": {"c"}}) == []                  # a chain; a self-import
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"c"}}) == [["a", "b"], ["c", "d"]]
    (tmp_path / "a.py").write_text("import weather_gym.probe.b\n")
    (tmp_path / "b.py").write_text("import weather_gym.probe.a\n")
    (tmp_path / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                   "    import weather_gym.probe.a\n")
    (tmp_path / "d.py").write_text("def f():\n    import weather_gym.probe.c\n")
    probe = {f"weather_gym.probe.{n}": tmp_path / f"{n}.py" for n in "abcd"}
    graph = module_graph(probe)
    assert graph["weather_gym.probe.c"] == set() and graph["weather_gym.probe.d"] == set()
    assert cycles(graph) == [["weather_gym.probe.a", "weather_gym.probe.b"]]   # planted: found
    (tmp_path / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                   "    import weather_gym.probe.a\n")
    assert cycles(module_graph(probe)) == []                                     # annotations only: no cycle


def test_no_import_cycle():
    found = cycles(module_graph(MODULES))
    assert not found, ("import cycles (move the shared piece into a module both import): "
                       + "; ".join(" <-> ".join(c) for c in found))


def layer_graph() -> dict[str, set[str]]:
    """Layer -> the layers its modules import (every import, inside functions too)."""
    graph: dict[str, set[str]] = {}
    for module, imports in IMPORTS.items():
        src = layer_of(module)
        for target, _, _ in imports:
            dst = layer_of(target)
            if dst is not None and dst != src:
                graph.setdefault(src, set()).add(dst)
    return graph


def test_no_arrow_up_a_layer():
    graph = layer_graph()
    found = cycles(graph)
    where = {(layer_of(m), layer_of(t)): f"{m} -> {t}" for m, imps in IMPORTS.items() for t, _, _ in imps}
    assert not found, "layers import each other (one of these arrows runs up): " + "; ".join(
        ", ".join(f"{a} -> {b} ({where[(a, b)]})" for a in c for b in sorted(graph.get(a, ())) if b in c)
        for c in found)



@pytest.mark.parametrize("module", ["weather_gym", "weather_gym.envs", "weather_gym.wrappers", "weather_gym.weather"])
def test_importing_the_package_does_not_load_matplotlib(module):
    """Plotting lives in modules only plotting callers import (``_figures``, ``track_plot``, the reports)."""
    import subprocess
    import sys

    probe = f"import {module}, sys; assert 'matplotlib' not in sys.modules, sorted(sys.modules)"
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, f"import {module} loads matplotlib: " + run.stderr[-400:]


def test_loading_a_track_does_not_load_numba():
    """The one-point projection's kernel (``_track_kernel``) is imported on first use: a tool that only
    reads, plots or projects arrays of a track does not pay numba's import (about a second)."""
    import subprocess
    import sys

    probe = ("import sys, numpy as np; from weather_gym.tracks import load_track; t = load_track('small_track'); "
             "t.project(np.array([1.0]), np.array([2.0])); assert 'numba' not in sys.modules; "
             "t.project(1.0, 2.0); assert 'numba' in sys.modules")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-600:]
