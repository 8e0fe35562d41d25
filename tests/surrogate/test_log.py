"""The full-pipeline log: its schema, the matching, a round trip through the file, bad files."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.core.errors import FileFormatError, InputError
from weather_gym.lab.training.surrogate.record import record
from weather_gym.surrogate.log import (
    CONE_COLUMNS,
    FP_COLUMNS,
    FRAME_COLUMNS,
    load_log,
    loose_matches,
    match_detections,
    save_log,
)
from weather_gym.weather.presets import preset_spec


@pytest.fixture(scope="module")
def small_log():
    return record(tracks=["hairpin"], weathers=["droplets@2"], seeds=[0], steps=12,
                  env_kwargs={"camera": {"width": 336, "height": 188}})


def test_schema(small_log):
    log = small_log
    for table, cols in ((log.cones, CONE_COLUMNS), (log.fps, FP_COLUMNS), (log.frames, FRAME_COLUMNS)):
        assert set(table) == set(cols)
        for k, dtype in cols.items():
            assert table[k].dtype == np.dtype(dtype), k
        assert len({len(v) for v in table.values()}) == 1
    c = log.cones
    assert len(log.frames["frame"]) == 13 and log.frames["frame"].tolist() == list(range(13))
    assert len(c["frame"]) == int(log.frames["n_gt"].sum()) > 0
    assert len(log.fps["frame"]) == int(log.frames["n_fp"].sum())
    det = c["detected"]
    assert det.any()
    assert np.isfinite(c["range_err"][det]).all() and np.isnan(c["range_err"][~det]).all()
    assert (c["det_cls"][~det] == -1).all() and (c["det_cls"][det] >= 0).all()
    assert ((c["visibility"] >= 0) & (c["visibility"] <= 1)).all()
    # a cone keeps its id from frame to frame
    ids0 = set(c["cone_id"][c["frame"] == 0].tolist())
    ids1 = set(c["cone_id"][c["frame"] == 1].tolist())
    assert len(ids0 & ids1) >= 0.8 * len(ids0)
    ep = log.episodes[0]
    k2 = preset_spec("droplets", 2)[0]["k"]  # the calibrated preset of the shipped detector
    assert (ep["condition"], ep["k"], ep["track"], ep["steps"]) == ("droplets", k2, "hairpin", 12)
    assert len(loose_matches(log)) == len(log.fps["frame"])


def test_round_trip_and_bad_files(small_log, tmp_path):
    path = save_log(small_log, tmp_path / "log.npz")
    back = load_log(path)
    for name in ("cones", "fps", "frames"):
        for k, v in getattr(small_log, name).items():
            np.testing.assert_array_equal(getattr(back, name)[k], v)
    assert back.episodes == small_log.episodes
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    data.pop("cones/range")
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(FileFormatError, match="missing column 'cones/range'"):
        load_log(tmp_path / "bad.npz")


def test_matching_is_greedy_by_score_and_class_agnostic():
    gt = np.array([[0, 0, 10, 20.], [30, 0, 40, 20.]])
    det = np.array([[0, 0, 10, 19.], [1, 0, 11, 20.], [30, 12, 40, 20.]])
    # the higher-scoring of two boxes on one cone takes it; a half-overlapping box is not a match
    assert match_detections(gt, det, np.array([0.5, 0.9, 0.8])).tolist() == [-1, 0, -1]


def test_two_effects_at_once_fail_before_driving():
    with pytest.raises(InputError, match="one weather effect at a time"):
        record(tracks=["hairpin"], weathers=["fog@2,droplets@3"], seeds=[0], steps=5)
