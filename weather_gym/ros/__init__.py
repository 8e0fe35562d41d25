"""ROS bags without ROS (the ``ros`` extra: ``rosbags``; docs/ros.md).

* :mod:`~weather_gym.ros.bags`: open rosbag1 / rosbag2 (SQLite, MCAP) bags with typed errors;
* :mod:`~weather_gym.ros.camera`: camera frames out of a bag (time window, every Nth, CameraInfo);
* :mod:`~weather_gym.ros.messages`: images to and from ``sensor_msgs``, the eufs cone messages;
* :mod:`~weather_gym.ros.degrade`: a bag with its camera weathered (``weather-gym degrade``);
* :mod:`~weather_gym.ros.episode_bag`: an episode as an MCAP bag (``weather-gym lap --bag``).

These modules import without ``rosbags`` installed (the library comes through
:mod:`weather_gym.ros._deps`, guarded); reading or writing a bag without it raises
:class:`~weather_gym.core.errors.MissingDependencyError` with the pip command.

Example:
    >>> from weather_gym.ros.bags import bag_kind
    >>> bag_kind("run_0412.bag"), bag_kind("run_0412.mcap"), bag_kind("frames.png")
    ('rosbag1', 'rosbag2', None)
"""
