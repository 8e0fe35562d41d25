"""Shared fixtures for the weather-gym test suite."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig

# The suite renders many thousands of EGL frames: it reuses PyBullet's shadow map between them (the
# opt-in of weather_gym.sim.egl.shadow_reuse, whose frames are the default's to the byte, which
# tests/sim/test_egl_shadow_reuse.py checks, as it checks that the default patches nothing). Set here,
# before any test runs, so that the suite's subprocesses inherit it too; WEATHER_GYM_SHADOW_MAP_REUSE=0
# runs the suite on the default path.
os.environ.setdefault("WEATHER_GYM_SHADOW_MAP_REUSE", "1")

SMALL_CAMERA = CameraConfig(width=96, height=54)
"""A tiny camera that keeps env tests fast (rendering dominates the step time)."""


REAL_FRAMES = "data/real/fskitti_estoril_autox2"
"""Real camera frames (GPL-3.0, validation only): read in place from the shared folder, never copied
into the repository; tests that need them skip when the folder is absent."""
REAL_INTRINSICS = "900.9,900.1,506.4,358.0"


def shared_dir() -> Path:
    """The read-only shared folder: ``$WEATHER_GYM_SHARED`` or ``<repo>/../shared``."""
    env = os.environ.get("WEATHER_GYM_SHARED")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(scope="session")
def real_frames_src() -> Path:
    """The FSKITTI Estoril frames (23 x 1024x768, KITTI labels); skips when absent."""
    src = shared_dir() / REAL_FRAMES
    if not (src / "images").is_dir() or not (src / "labels").is_dir():
        pytest.skip(f"real frames not found at {src} (set WEATHER_GYM_SHARED)")
    return src


@pytest.fixture(scope="session")
def real_dataset(real_frames_src, tmp_path_factory) -> Path:
    """The real frames imported once per session (into pytest's temporary folder), with the proposed
    ego-vehicle mask stored; condition clear."""
    from weather_gym.lab.datasets.coco import load_coco
    from weather_gym.lab.datasets.importers import import_dataset
    from weather_gym.lab.datasets.masks import propose_mask, set_dataset_mask, write_mask

    out = tmp_path_factory.mktemp("real") / "clear"
    import_dataset("kitti", real_frames_src, out, intrinsics=REAL_INTRINSICS, condition="clear")
    ds = load_coco(out)
    mask_png = out.parent / "proposed_mask.png"
    write_mask(mask_png, propose_mask([ds.image(i) for i in range(len(ds))]))
    set_dataset_mask(out, mask_png)
    return out


@pytest.fixture(autouse=True, scope="session")
def _pool_presets_and_private_cache(tmp_path_factory):
    """The suite pins the shipped pool presets (``WEATHER_GYM_PRESETS=pool``): a ``CONDITION@SEVERITY`` in a
    test that does not test resolution reads the pool's k and resolves nothing (the default, presets
    resolved per scenario, costs about a minute per new scenario). The tests of the default unset it
    themselves (tests/lab/calibration/test_resolve.py, tests/pipeline/test_presets_default.py). A
    resolution, where a test runs one, caches into a session folder, never the user's cache."""
    saved = {k: os.environ.get(k) for k in ("WEATHER_GYM_PRESETS", "WEATHER_GYM_CACHE")}
    os.environ["WEATHER_GYM_PRESETS"] = "pool"
    os.environ["WEATHER_GYM_CACHE"] = str(tmp_path_factory.mktemp("weather-gym-cache"))
    yield
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def small_camera() -> CameraConfig:
    return SMALL_CAMERA


@pytest.fixture
def make_env():
    """Factory for ``ConeTrackEnv`` (registered id by default) that closes every env it made."""
    import gymnasium as gym

    import weather_gym  # noqa: F401  (registers the ids)

    made = []

    def _make(env_id: str = "WeatherGym/ConeTrack-v0", **kwargs):
        kwargs.setdefault("camera", SMALL_CAMERA)
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()


def drive_gt(env, seed: int = 0, max_steps: int = 100_000, options: dict | None = None):
    """Run the ground-truth pure-pursuit driver for one episode; returns (steps, last info, actions)."""
    from weather_gym.agents import AGENTS

    obs, info = env.reset(seed=seed, options=options)
    u = env.unwrapped
    agent = AGENTS.get("gt_pure_pursuit")(u.track, u.config.camera)
    agent.reset(seed=seed, info=info)
    actions = []
    for step in range(1, max_steps + 1):
        a = agent.act(obs, info)
        actions.append(np.asarray(a, np.float32))
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            return step, info, actions
    return max_steps, info, actions
