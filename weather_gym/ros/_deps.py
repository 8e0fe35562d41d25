"""The optional ROS bag library (the ``ros`` extra: ``rosbags``), imported on first use, guarded: the
rest of weather-gym never needs it, commands that do not touch a bag do not load it, and a bag read or
written without it raises :class:`~weather_gym.core.errors.MissingDependencyError` naming the pip command.

Example:
    >>> from weather_gym.ros._deps import lib
    >>> lib("weather-gym degrade BAG").rosbag2.StoragePlugin.MCAP.name  # the ros extra is installed here
    'MCAP'
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from weather_gym.core.errors import MissingDependencyError

__all__ = ["INSTALL", "latched_qos", "lib", "require"]

INSTALL = "pip install 'weather-gym[ros]' (or: pip install rosbags mcap mcap-ros2-support)"

_LIB: Any = None
"""The loaded library (a namespace), ``False`` when its import failed, None before the first use."""


def lib(what: str = "weather-gym's ROS bag support") -> SimpleNamespace:
    """``rosbags``' pieces weather-gym uses (``AnyReader``, ``rosbag1``, ``rosbag2``, the typestore
    functions, the QoS types); ``what``: who needs them, for the error when it is not installed."""
    global _LIB
    if _LIB is None:
        try:
            from rosbags import interfaces, rosbag1, rosbag2
            from rosbags.highlevel import AnyReader, AnyReaderError
            from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        except ImportError:  # the ros extra is not installed
            _LIB = False
        else:
            _LIB = SimpleNamespace(AnyReader=AnyReader, AnyReaderError=AnyReaderError, rosbag1=rosbag1,
                                   rosbag2=rosbag2, Stores=Stores, get_types_from_msg=get_types_from_msg,
                                   get_typestore=get_typestore, interfaces=interfaces)
    if _LIB is False:
        raise MissingDependencyError(f"{what} reads and writes ROS bags with the rosbags package, which is not "
                                     f"installed: {INSTALL}")
    return _LIB


def require(what: str) -> None:
    """Raise :class:`MissingDependencyError` when ``rosbags`` is not installed (``what``: who needs it)."""
    lib(what)


def latched_qos() -> Any:
    """The QoS of a latched topic (``/tf_static``, a map): reliable, transient local, keep last 1."""
    i = lib().interfaces
    zero = i.QosTime(0, 0)
    return i.Qos(i.QosHistory.KEEP_LAST, 1, i.QosReliability.RELIABLE, i.QosDurability.TRANSIENT_LOCAL, zero, zero,
                 i.QosLiveliness.AUTOMATIC, zero, False)
