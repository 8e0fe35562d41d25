"""Fixtures of the gap tests: one clean paired set rendered per session, measured copies with hidden weather."""

from __future__ import annotations

import pytest
from gap_cases import CLEAN_FRAMES, GAP_CAMERA, MEASURED_SEED


@pytest.fixture(scope="session")
def gap_root(tmp_path_factory):
    return tmp_path_factory.mktemp("gap")


@pytest.fixture(scope="session")
def clean_dir(gap_root):
    """40 clean frames at 336x188 on small_track, random looks, rendered once."""
    from weather_gym.datasets import render_dataset

    out = gap_root / "clean"
    render_dataset(out, tracks=["small_track"], frames=CLEAN_FRAMES, seed=11, randomize=True,
                   frames_per_episode=10, camera=GAP_CAMERA, progress=False)
    return out


@pytest.fixture(scope="session")
def gap_cache(gap_root):
    """Clean renders of the gap workflow, shared by every run (the measured copies share their views)."""
    return gap_root / "cache"


@pytest.fixture(scope="session")
def make_measured(clean_dir, gap_root):
    """``make_measured(tag, weather, strip_poses=False)``: a copy of the clean set with ``weather`` applied."""
    from weather_gym.gap.synthetic import degrade_dataset

    made = {}

    def _make(tag: str, weather, strip_poses: bool = False):
        if tag not in made:
            out = gap_root / f"measured_{tag}"
            degrade_dataset(clean_dir, out, weather, seed=MEASURED_SEED, strip_poses=strip_poses)
            made[tag] = out
        return made[tag]

    return _make


@pytest.fixture
def write_model(tmp_path):
    """``write_model(text)``: a model TOML file in the test's folder."""
    def _write(text: str, name: str = "model.toml"):
        p = tmp_path / name
        p.write_text(text)
        return p

    return _write
