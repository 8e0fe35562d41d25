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
    from rosbags.interfaces import ConnectionExtRosbag1, ConnectionExtRosbag2
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError:  # the ros extra is not installed
    rosbag1 = rosbag2 = AnyReader = AnyReaderError = None  # type: ignore[assignment]
    ConnectionExtRosbag1 = ConnectionExtRosbag2 = Stores = get_types_from_msg = get_typestore = None  # type: ignore[assignment]

__all__ = ["AnyReader", "AnyReaderError", "ConnectionExtRosbag1", "ConnectionExtRosbag2", "Stores",
           "get_types_from_msg", "get_typestore", "require", "rosbag1", "rosbag2"]

INSTALL = "pip install 'weather-gym[ros]' (or: pip install rosbags mcap mcap-ros2-support)"


def require(what: str) -> None:
    """Raise :class:`MissingDependencyError` when ``rosbags`` is not installed (``what``: who needs it)."""
    if AnyReader is None:
        raise MissingDependencyError(f"{what} reads and writes ROS bags with the rosbags package, which is not "
                                     f"installed: {INSTALL}")
