"""Fixtures of the gap tests: one clean paired set rendered per session, measured copies with hidden weather,
and "real-looking" sets of another domain (look, camera, exposure, the car's own bodywork in view)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gap_cases import CLEAN_FRAMES, GAP_CAMERA, MEASURED_SEED, SHIFTED_FRAMES

from weather_gym.camera.isp import CameraModel


@pytest.fixture(scope="session")
def gap_root(tmp_path_factory):
    return tmp_path_factory.mktemp("gap")


@pytest.fixture(scope="session")
def clean_dir(gap_root):
    """40 clean frames at 336x188 on small_track, random looks, rendered once: the plain world with the
    ideal camera, so that a hidden effect is the only thing in the frames besides the scene (the
    realistic world's sensor noise and JPEG mask some effects: see test_gap_realistic.py)."""
    from weather_gym.lab.datasets import render_dataset

    out = gap_root / "clean"
    render_dataset(out, tracks=["small_track"], frames=CLEAN_FRAMES, seed=11, randomize=True,
                   frames_per_episode=10, camera=GAP_CAMERA, progress=False, scene="plain",
                   camera_model=CameraModel.ideal())
    return out


@pytest.fixture(scope="session")
def gap_cache(gap_root):
    """Clean renders of the gap workflow, shared by every run (the measured copies share their views)."""
    return gap_root / "cache"


@pytest.fixture(scope="session")
def make_measured(clean_dir, gap_root):
    """``make_measured(tag, weather, strip_poses=False)``: a copy of the clean set with ``weather`` applied."""
    from weather_gym.lab.gap.synthetic import degrade_dataset

    made = {}

    def _make(tag: str, weather, strip_poses: bool = False):
        if tag not in made:
            out = gap_root / f"measured_{tag}"
            degrade_dataset(clean_dir, out, weather, seed=MEASURED_SEED, strip_poses=strip_poses)
            made[tag] = out
        return made[tag]

    return _make


@pytest.fixture(scope="session")
def realistic_clean_dir(gap_root):
    """40 clean frames of the realistic world and camera model, random looks and cameras."""
    from weather_gym.lab.datasets import render_dataset

    out = gap_root / "realistic_clean"
    render_dataset(out, tracks=["small_track"], frames=CLEAN_FRAMES, seed=13, randomize=True,
                   frames_per_episode=10, camera=GAP_CAMERA, progress=False, scene="realistic")
    return out


@pytest.fixture
def write_model(tmp_path):
    """``write_model(text)``: a model TOML file in the test's folder."""
    def _write(text: str, name: str = "model.toml"):
        p = tmp_path / name
        p.write_text(text)
        return p

    return _write


def _ego_overlay(w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """A static car (dark cockpit, white nose) over the lower part of the frame, and its mask."""
    import cv2

    rng = np.random.default_rng(7)
    mask = np.zeros((h, w), np.uint8)
    body = np.array([[0, h], [int(0.1 * w), int(0.72 * h)], [int(0.38 * w), int(0.62 * h)],
                     [int(0.62 * w), int(0.62 * h)], [int(0.9 * w), int(0.72 * h)], [w, h]], np.int32)
    cv2.fillPoly(mask, [body], 1)
    car = np.full((h, w, 3), (40, 40, 44), np.uint8)
    nose = np.array([[int(0.4 * w), int(0.63 * h)], [int(0.6 * w), int(0.63 * h)], [int(0.66 * w), h],
                     [int(0.34 * w), h]], np.int32)
    cv2.fillPoly(car, [nose], (215, 210, 205))
    car = np.clip(car.astype(np.int16) + rng.integers(-12, 13, car.shape), 0, 255).astype(np.uint8)
    return car, mask.astype(bool)


@pytest.fixture(scope="session")
def shifted(gap_root):
    """Two clear sets ("clear_a", "clear_b", other frames) of a real-looking domain made from the simulator
    (the plain world, ideal camera): random looks, another camera (70 deg, lower, pitched down), over-exposed with a contrastier tone curve,
    the car's own bodywork in the lower part of every frame (its ignore mask stored), no poses, looks or
    camera records (a recording of unknown intrinsics)."""
    import cv2

    from weather_gym.camera.config import CameraConfig
    from weather_gym.lab.datasets import load_coco, render_dataset
    from weather_gym.lab.datasets.coco import ANNOTATIONS
    from weather_gym.lab.datasets.masks import MASK_FILE, write_mask
    from weather_gym.lab.gap.weather_model import apply_chain
    from weather_gym.weather import make

    root = gap_root / "shifted"
    w, h = GAP_CAMERA.width, GAP_CAMERA.height
    cam = CameraConfig(width=w, height=h, hfov_deg=70.0, pitch_deg=7.0, mount_height=0.8)
    render_dataset(root / "raw", tracks=["small_track"], frames=2 * SHIFTED_FRAMES, seed=21, randomize=True,
                   frames_per_episode=6, camera=cam, progress=False, scene="plain", camera_model=CameraModel.ideal())
    ds = load_coco(root / "raw")
    data = json.loads((root / "raw" / ANNOTATIONS).read_text())
    over = make("exposure", k=0.45, direction="over", contrast=0.4)
    car, mask = _ego_overlay(w, h)
    out = {}
    for name, idx in (("clear_a", range(SHIFTED_FRAMES)), ("clear_b", range(SHIFTED_FRAMES, 2 * SHIFTED_FRAMES))):
        d = root / name
        (d / "images").mkdir(parents=True)
        recs = []
        for i in idx:
            img = apply_chain([over], ds.image(i), depth=None, state={}, seed=0, frame_id=i)
            img[mask] = car[mask]
            rec = {k: v for k, v in ds.record(i).items() if k in ("id", "file_name", "width", "height")}
            assert cv2.imwrite(str(d / rec["file_name"]), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            recs.append(rec)
        write_mask(d / MASK_FILE, mask)
        ids = {r["id"] for r in recs}
        info = {"description": "domain-shifted simulator frames", "origin": "external", "ignore_mask": MASK_FILE}
        (d / ANNOTATIONS).write_text(json.dumps({
            "info": info, "images": recs, "annotations": [a for a in data["annotations"] if a["image_id"] in ids],
            "categories": data["categories"]}))
        out[name] = d
    return out
