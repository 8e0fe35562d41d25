import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.perception.fusion import NearestNeighbourFusion, SensorCones


def cones(x, y, classes, scores, source=0):
    return SensorCones.of(x=x, y=y, classes=classes, scores=scores, source=source)


def test_pairs_take_lidar_position_camera_colour_and_noisy_or_confidence():
    cam = cones([10.4, 6.0], [2.0, -1.5], [1, 0], [0.6, 0.9])
    lid = cones([6.1, 10.0], [-1.4, 2.1], [-1, -1], [0.5, 0.5], 1)
    f = NearestNeighbourFusion()(cam, lid)
    assert f.x.tolist() == [6.1, 10.0] and f.y.tolist() == [-1.4, 2.1]
    assert f.classes.tolist() == [0, 1] and f.source.tolist() == [2, 2]
    assert f.scores == pytest.approx([1 - 0.1 * 0.5, 1 - 0.4 * 0.5])


def test_the_gate_grows_with_range_and_each_cone_is_used_once():
    rule = NearestNeighbourFusion(gate_m=0.5, gate_rel=0.1)
    # at 20 m the gate is 2.5 m: a camera cone 2 m off still pairs; at 5 m (gate 1 m) it does not
    assert rule(cones([22.0], [0.0], [1], [0.9]), cones([20.0], [0.0], [-1], [1.0], 1)).source.tolist() == [2]
    f = rule(cones([7.0], [0.0], [1], [0.9]), cones([5.0], [0.0], [-1], [1.0], 1))
    assert sorted(f.source.tolist()) == [0, 1]
    # two LiDAR cones near one camera cone: the nearer pairs, the other stays of unknown colour
    f = rule(cones([5.0], [0.0], [0], [0.9]), cones([5.2, 5.5], [0.0, 0.0], [-1, -1], [1.0, 1.0], 1))
    assert f.x.tolist() == [5.2, 5.5] and f.classes.tolist() == [0, -1]


def test_lone_camera_cones_need_a_score_and_empty_lists_work():
    rule = NearestNeighbourFusion(camera_only_score=0.5)
    f = rule(cones([30.0, 25.0], [0.0, 1.0], [0, 1], [0.4, 0.6]), cones([], [], [], [], 1))
    assert f.x.tolist() == [25.0] and f.classes.tolist() == [1]
    assert len(rule(cones([], [], [], []), cones([], [], [], [], 1))) == 0
    with pytest.raises(InputError, match="gate_m"):
        NearestNeighbourFusion(gate_m=-1)
    with pytest.raises(InputError, match="one entry per cone"):
        SensorCones.of(x=[1.0], y=[], classes=[0], scores=[1.0])
    assert isinstance(rule(cones([1.0], [0.0], [0], [0.9]), cones([1.0], [0.0], [-1], [1.0], 1)).x, np.ndarray)
