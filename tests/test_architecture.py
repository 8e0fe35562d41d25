"""The layers contract of docs/architecture.md, checked on every import of every module.

Every ``import`` statement of the package is read from its source (those inside functions and
methods too), so an upward dependency cannot hide in a function body. Three rules:

1. a layer imports only the layers the table allows (``ALLOWED``);
2. the heavy packages are imported only where the table allows them (``HEAVY``): PyBullet in the
   simulator, onnxruntime in perception, torch/onnx in training and the SB3 feature extractor, Ray in
   the evaluation runner;
3. everything else is imported at module level: an import inside a function is only for those heavy,
   optional packages (or a module of ours that imports one of them at module level), or an optional
   dependency guarded by ``try: import x`` / ``except ImportError`` (PyYAML, PyAV, fcntl).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "weather_gym"

PLUMBING = {"registry", "_io", "errors", "limits", "paths", "cone_spec", "cone_arrays", "_lazy", "_toml",
            "_lock", "_confine"}
"""Shared plumbing with no layer of its own: importable from anywhere, imports no layer."""

SUBLAYERS = {"perception.train": "perception_tools", "perception.conenet": "perception_tools",
             "perception.plots": "perception_tools",
             "surrogate.record": "surrogate_tools", "surrogate.validate": "surrogate_tools"}
"""Modules that sit above their package's layer: training and dataset-level reports need datasets;
the surrogate's logging and validation drive full-pipeline episodes (a top layer, like evaluation)."""

LOWER = {"plumbing"}
ALLOWED: dict[str, set[str]] = {
    "plumbing": set(),
    "tracks": set(),
    "camera": set(),
    "weather": set(),
    "sim": {"tracks", "camera"},
    "envs": {"sim", "tracks", "camera", "weather"},
    "perception": {"camera", "weather"},
    "surrogate": {"perception", "weather", "camera"},
    "wrappers": {"weather", "perception", "camera", "surrogate"},
    "pipeline": {"envs", "weather", "wrappers", "root"},
    "agents": {"tracks", "camera", "perception", "wrappers"},
    "datasets": {"envs", "sim", "tracks", "camera", "weather", "perception", "pipeline", "agents"},
    "perception_tools": {"perception", "datasets", "camera", "weather"},
    "viz": {"perception", "camera", "tracks"},
}
"""Layer -> the layers it may import (besides itself and the plumbing). Layers not listed here
(evaluation, calibration, gap, bench, cli, the package root) sit on top and may import any layer below
them, but not the CLI (only ``cli`` itself does)."""

TOP = {"evaluation", "calibration", "gap", "bench", "cli", "root", "surrogate_tools", "rl"}

HEAVY: dict[str, set[str]] = {
    "pybullet": {"sim"},
    "pybullet_data": {"sim"},
    "onnxruntime": {"perception", "bench"},
    "torch": {"perception_tools", "agents", "bench", "rl"},
    "onnx": {"perception_tools"},
    "ray": {"evaluation", "cli"},
    "stable_baselines3": {"agents", "rl"},
    "numba": {"sim", "surrogate"},
}
"""Heavy package -> the layers that may import it. ``bench`` compares against a torch baseline;
``agents`` holds the SB3 feature extractor (a torch module); ``numba`` compiles the geometric ground
truth (``sim.visibility``) and the surrogate's per-step draws (``surrogate.sample``, ``surrogate.model``'s
crowding) and stays out of the other layers (a compile costs seconds on a cold cache)."""

NEVER_IMPORTED_BY: dict[str, set[str]] = {"gymnasium": {"tracks", "camera", "sim", "weather"}}


def _modules() -> dict[str, Path]:
    out = {}
    for f in sorted(PACKAGE.rglob("*.py")):
        name = ".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = f
    return out


MODULES = _modules()


def layer_of(module: str) -> str | None:
    """The layer of a ``weather_gym`` module (None for anything else)."""
    parts = module.split(".")
    if parts[0] != "weather_gym":
        return None
    if len(parts) == 1:
        return "root"
    rest = ".".join(parts[1:])
    for prefix, sub in SUBLAYERS.items():
        if rest == prefix or rest.startswith(prefix + "."):
            return sub
    head = parts[1]
    if head in PLUMBING:
        return "plumbing"
    if head in ("tracks", "_track_geometry"):
        return "tracks"
    if head in ("camera_config", "camera_isp"):
        return "camera"
    if head == "__version__":
        return "root"
    return head


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
    assert layer_of("weather_gym.perception.train") == "perception_tools"
    assert layer_of("weather_gym.errors") == "plumbing"
    assert layer_of("numpy") is None


@pytest.mark.parametrize("module", sorted(MODULES))
def test_layers_import_only_what_the_table_allows(module):
    src = layer_of(module)
    bad = []
    for target, line, _ in IMPORTS[module]:
        dst = layer_of(target)
        if dst is None or dst == src or dst == "plumbing":
            continue
        if src == "plumbing":
            bad.append((line, target, "plumbing imports no layer"))
        elif dst == "cli" and src not in ("cli", "bench"):
            bad.append((line, target, "only the CLI (and the bench commands it runs) imports the CLI"))
        elif src in TOP:
            continue
        elif dst not in ALLOWED.get(src, set()):
            bad.append((line, target, f"layer {src!r} may import only {sorted(ALLOWED.get(src, set()))}"))
    assert not bad, f"{module}: " + "; ".join(f"line {ln}: imports {t} ({why})" for ln, t, why in bad)


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
             "import weather_gym.perception.train, weather_gym.datasets.coco\n")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
