"""Guards of the gap workflow: fits on a bound are flagged, parsimony drops effects the data does not
need, too few frames and mismatched inputs are clear errors, the report says which mode ran and why."""

from __future__ import annotations

import json
import shutil

import pytest
from gap_cases import FAST

from weather_gym.lab.gap.workflow import GapConfig, GapSession, run_gap

pytestmark = pytest.mark.slow


def test_a_fit_on_a_bound_is_flagged_and_not_added(make_measured, gap_cache, tmp_path):
    """Strong dimming with only vignetting allowed: vignetting helps, but only at the edge of its range."""
    measured = make_measured("dim_strong", [{"name": "dim", "k": 0.85}])
    report = run_gap(measured, None, tmp_path / "out", GapConfig(candidates=("vignette",), perception=False, **FAST),
                     cache_dir=gap_cache, plots=False)
    assert report["missing_effects"] == []
    assert [f["candidate"] for f in report["flagged"]] == ["vignette"]
    assert any("k = 1" in b or "bound of" in b for b in report["flagged"][0]["bounds"])
    assert "flagged" in report["verdict"]


def test_parsimony_drops_an_effect_the_data_does_not_contain(make_measured, gap_cache):
    """Droplets forced in ahead of the right effect (vignetting): the check after the loop drops them."""
    from weather_gym.lab.gap.simulate import simulate

    measured = make_measured("vignette_p", [{"name": "vignette", "k": 0.6, "exponent": 3.0}])
    s = GapSession(simulate(measured, cache_dir=gap_cache), [], GapConfig(perception=False, **FAST))
    s.add(s.diagnose(names=["droplets"])[0], force=True)
    s.add(s.diagnose(names=["vignette"])[0])
    assert [e.name for e in s.model] == ["droplets", "vignette"]
    dropped = s.prune()
    assert [d["name"] for d in dropped] == ["droplets"]
    assert [e.name for e in s.model] == ["vignette"]
    assert s.report()["missing_effects"] == ["vignette"]


def test_too_few_frames_is_an_error_naming_the_minimum(clean_dir, tmp_path):
    from weather_gym.lab.datasets.coco import ANNOTATIONS

    data = json.loads((clean_dir / ANNOTATIONS).read_text())
    small = tmp_path / "small"
    (small / "images").mkdir(parents=True)
    (small / "depth").mkdir()
    images = data["images"][:5]
    for im in images:
        shutil.copyfile(clean_dir / im["file_name"], small / im["file_name"])
        shutil.copyfile(clean_dir / im["depth_file"], small / im["depth_file"])
    ids = {im["id"] for im in images}
    (small / ANNOTATIONS).write_text(json.dumps({**data, "images": images,
                                                 "annotations": [a for a in data["annotations"] if a["image_id"] in ids]}))
    with pytest.raises(ValueError, match=r"needs at least 8 measured frames \(half to fit, half held out\), found 5"):
        run_gap(small, None, tmp_path / "out", GapConfig(**FAST))
    assert not (tmp_path / "out" / "report.json").exists()


def test_mode_errors_name_what_is_missing(shifted, clean_dir, tmp_path):
    with pytest.raises(ValueError, match="mode same-camera needs --reference CLEAR_DIR"):
        run_gap(shifted["clear_b"], None, tmp_path / "a", GapConfig(mode="same-camera", **FAST))
    with pytest.raises(ValueError, match="--reference .* goes with mode same-camera or did, not paired"):
        run_gap(shifted["clear_b"], None, tmp_path / "b", GapConfig(mode="paired", **FAST), reference=shifted["clear_a"])
    with pytest.raises(ValueError, match="must come from the same camera at the same size"):
        run_gap(shifted["clear_b"], None, tmp_path / "c", GapConfig(**FAST), reference=_resized(shifted["clear_a"], tmp_path))
    with pytest.raises(ValueError, match="the records name no track; the simulator needs one"):
        run_gap(shifted["clear_b"], None, tmp_path / "d", GapConfig(mode="did", **FAST), reference=shifted["clear_a"])


def _resized(src, tmp_path):
    import cv2

    from weather_gym.lab.datasets.coco import ANNOTATIONS

    data = json.loads((src / ANNOTATIONS).read_text())
    out = tmp_path / "resized"
    (out / "images").mkdir(parents=True)
    for im in data["images"]:
        img = cv2.imread(str(src / im["file_name"]))
        cv2.imwrite(str(out / im["file_name"]), cv2.resize(img, (168, 94)))
        im["width"], im["height"] = 168, 94
    data["info"].pop("ignore_mask")
    (out / ANNOTATIONS).write_text(json.dumps(data))
    return out
