"""The optional ROS bag libraries (the ``ros`` extra), imported once, guarded: the rest of weather-gym
never needs them, and a ROS command without them raises
:class:`~weather_gym.errors.MissingDependencyError` naming the pip command.

Example:
    >>> from weather_gym.ros._deps import require
    >>> require("weather-gym degrade BAG") is None  # the ros extra is installed here
    True
"""

from __future__ import annotations

from weather_gym.errors import MissingDependencyError

try:
    from rosbags import rosbag1, rosbag2
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.interfaces import (
        ConnectionExtRosbag1,
        ConnectionExtRosbag2,
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError:  # the ros extra is not installed
    rosbag1 = rosbag2 = AnyReader = AnyReaderError = None  # type: ignore[assignment]
    ConnectionExtRosbag1 = ConnectionExtRosbag2 = Stores = get_types_from_msg = get_typestore = None  # type: ignore[assignment]
    Qos = QosDurability = QosHistory = QosLiveliness = QosReliability = QosTime = None  # type: ignore[assignment]

__all__ = ["AnyReader", "AnyReaderError", "ConnectionExtRosbag1", "ConnectionExtRosbag2", "Qos", "QosDurability",
           "QosHistory", "QosLiveliness", "QosReliability", "QosTime", "Stores",
           "get_types_from_msg", "get_typestore", "latched_qos", "require", "rosbag1", "rosbag2"]

INSTALL = "pip install 'weather-gym[ros]' (or: pip install rosbags mcap mcap-ros2-support)"


def latched_qos() -> object:
    """The QoS of a latched topic (``/tf_static``, a map): reliable, transient local, keep last 1."""
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


def require(what: str) -> None:
    """Raise :class:`MissingDependencyError` when ``rosbags`` is not installed (``what``: who needs it)."""
    if AnyReader is None:
        raise MissingDependencyError(f"{what} reads and writes ROS bags with the rosbags package, which is not "
                                     f"installed: {INSTALL}")
