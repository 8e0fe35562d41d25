"""Installed anywhere: numba's disk cache only where a cache folder is writable (weather_gym.core._jit_cache).

The end-to-end test runs a real ``weather-gym degrade`` (the refractive drops, the sensor noise and the
motion smear: three compiled kernels), imports every module that compiles one and steps a
``gym.make`` env in weather, with the package folder bind-mounted read-only, the root file system
read-only (``TMPDIR`` the one writable folder) and ``HOME=/nonexistent`` (in a private mount namespace:
``unshare --mount``, as root), and checks the frame is the one a normal run writes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import weather_gym
import weather_gym.core._jit_cache as jc

PACKAGE = Path(weather_gym.__file__).resolve().parent
JIT_MODULES = sorted(
    ".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts)
    for p in PACKAGE.rglob("*.py") if "njit(cache=jit_cache(__file__)" in p.read_text())
COMMAND = ["degrade", "in.png", "out.png", "--weather", "droplets:0.7:mode=refractive,noise:0.5,motion_blur:0.5",
           "--seed", "1"]

SCRIPT = r"""set -e
mount --bind "$OUT" "$OUT"
mount --bind -o ro "$PKG" "$PKG"
mount -o remount,bind,ro /
cd "$OUT"
"$PY" -m weather_gym.cli "$@"
"$PY" -c "import importlib, sys; [importlib.import_module(m) for m in sys.argv[1].split(',')]; print('imported')" "$MODULES"
"$PY" -c "$GYM"
"""

GYM = """
import gymnasium as gym, weather_gym
env = gym.make('WeatherGym/ConeTrackSmall-v0', camera={'width': 64, 'height': 36},
               weather='droplets:0.6:mode=refractive,noise:0.4')
env.reset(seed=0)
for _ in range(3):
    obs = env.step(env.action_space.sample())[0]
env.close()
print('stepped', obs['image'].shape)
"""


def _unshare_reason() -> str | None:
    if not sys.platform.startswith("linux"):
        return "mount namespaces are Linux only"
    if os.geteuid() != 0:
        return "needs root for a mount namespace (unshare --mount)"
    if shutil.which("unshare") is None or shutil.which("mount") is None:
        return "unshare/mount not installed"
    probe = subprocess.run(["unshare", "--mount", "mount", "--bind", "-o", "ro", "/", "/mnt"], capture_output=True,
                           text=True)
    if probe.returncode != 0:
        return f"unshare --mount unavailable here: {probe.stderr.strip()}"
    return None


def test_every_compiled_module_asks_jit_cache():
    assert len(JIT_MODULES) >= 4, JIT_MODULES
    offenders = [str(p) for p in PACKAGE.rglob("*.py") if "cache=True" in p.read_text() and p.name != "_jit_cache.py"]
    assert offenders == []


def test_no_writable_folder_means_no_cache_and_one_note(tmp_path, monkeypatch, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    (ro / "mod.py").write_text("")
    ro.chmod(0o555)
    monkeypatch.setattr(jc, "_writable", lambda folder: False)  # root writes anywhere: pretend
    jc._decide.cache_clear()
    jc._note.cache_clear()
    try:
        assert jc.jit_cache(ro / "mod.py") is False
        assert jc.jit_cache(tmp_path / "other.py") is False
        err = capsys.readouterr().err
        assert err.count("note: numba finds no writable cache folder") == 1
    finally:
        jc._decide.cache_clear()
        jc._note.cache_clear()


def test_numba_cache_dir_is_tried_first_and_a_broken_one_is_not_fatal(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    assert jc.cache_folders(tmp_path / "m.py")[0] == str(tmp_path / "cache")
    assert jc._writable(str(tmp_path / "cache"))
    (tmp_path / "file").write_text("")
    assert not jc._writable(str(tmp_path / "file" / "sub"))  # a file in the way: no, and no exception
    assert not jc._writable("bad\0name")


def test_runs_from_a_read_only_install_with_no_home(tmp_path):
    reason = _unshare_reason()
    if reason:
        pytest.skip(reason)
    rng = np.random.default_rng(0)
    assert cv2.imwrite(str(tmp_path / "in.png"), (rng.random((72, 96, 3)) * 255).astype(np.uint8))
    ro_out = tmp_path / "ro"
    ro_out.mkdir()
    shutil.copy(tmp_path / "in.png", ro_out / "in.png")
    env = {"PATH": "/usr/bin:/bin", "HOME": "/nonexistent", "PYTHONDONTWRITEBYTECODE": "1", "TMPDIR": str(ro_out),
           "GYM": GYM,
           "PYTHONPATH": str(PACKAGE.parent), "OUT": str(ro_out), "PKG": str(PACKAGE), "PY": sys.executable,
           "MODULES": ",".join(JIT_MODULES)}
    run = subprocess.run(["unshare", "--mount", "sh", "-c", SCRIPT, "sh", *COMMAND], env=env, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "imported" in run.stdout and "stepped (36, 64, 3)" in run.stdout
    assert run.stderr.count("note: numba finds no writable cache folder") == 3, run.stderr  # one per process
    assert not Path("/nonexistent").exists()
    normal = subprocess.run([sys.executable, "-m", "weather_gym.cli", *COMMAND], cwd=tmp_path, capture_output=True,
                            text=True, env={**os.environ, "PYTHONPATH": str(PACKAGE.parent)}, timeout=300)
    assert normal.returncode == 0, normal.stderr[-3000:]
    assert "numba finds no writable" not in normal.stderr
    assert (ro_out / "out.png").read_bytes() == (tmp_path / "out.png").read_bytes()
