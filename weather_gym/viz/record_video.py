"""``RecordVideo``: Gymnasium's episode/step-triggered video recording, written as H.264 frame by frame.

The same triggers and file names as ``gymnasium.wrappers.RecordVideo`` (``episode_trigger``,
``step_trigger``, ``video_length``, ``name_prefix``; ``{prefix}-episode-{n}.mp4``), without its
MoviePy dependency and without holding the episode's frames in memory: every frame goes straight to a
:class:`~weather_gym.viz.video.VideoWriter` (H.264 through PyAV). A video that exists is never
replaced unless ``overwrite=True``.

With ``render_view="camera"`` and a ``WeatherWrapper`` in the stack, ``render()`` is the weathered
frame the agent sees, so the video shows the weather.

Example:
    >>> import gymnasium as gym, tempfile, weather_gym
    >>> from weather_gym.wrappers import RecordVideo
    >>> env = gym.make("WeatherGym/ConeTrack-v0", render_mode="rgb_array", render_view="camera",
    ...                weather="rain@2", camera={"width": 160, "height": 90})          # doctest: +SKIP
    >>> env = RecordVideo(env, tempfile.mkdtemp(), episode_trigger=lambda n: True)    # doctest: +SKIP
    >>> obs, info = env.reset(seed=0)                                                  # doctest: +SKIP
    >>> for _ in range(30): obs, *_ = env.step(env.action_space.sample())             # doctest: +SKIP
    >>> env.close()                       # writes rl-video-episode-0.mp4 (31 frames)  # doctest: +SKIP

Which episodes the default trigger records (Gymnasium's ``capped_cubic_video_schedule``):
    >>> [n for n in range(100) if capped_cubic_video_schedule(n)]
    [0, 1, 8, 27, 64]
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.viz.video import VideoWriter

__all__ = ["RecordVideo"]


def capped_cubic_video_schedule(episode_id: int) -> bool:
    """Gymnasium's default trigger (episodes 0, 1, 8, 27, ... below 1000, then every 1000th),
    kept here because ``gymnasium.utils.save_video`` needs moviepy, which this wrapper does not."""
    if episode_id < 1000:
        return int(round(episode_id ** (1.0 / 3))) ** 3 == episode_id
    return episode_id % 1000 == 0


class RecordVideo(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Record ``env.render()`` frames of chosen episodes or step ranges to MP4 files (see the module doc).

    Args:
        env: an env with ``render_mode="rgb_array"``.
        video_folder: where the videos go (created if missing).
        episode_trigger: ``f(episode_index) -> bool``: record this episode (default: Gymnasium's
            ``capped_cubic_video_schedule``, episodes 0, 1, 8, 27, ... then every 1000th).
        step_trigger: ``f(step_index) -> bool``: start a recording at this step.
        video_length: frames per video (0: whole episodes).
        name_prefix: file name prefix.
        fps: frame rate (default: the env's ``metadata["render_fps"]``, else 30).
        overwrite: replace videos that exist.
    """

    def __init__(self, env: gym.Env, video_folder: str | os.PathLike, episode_trigger: Callable[[int], bool] | None = None,
                 step_trigger: Callable[[int], bool] | None = None, video_length: int = 0,
                 name_prefix: str = "rl-video", fps: float | None = None, overwrite: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, video_folder=video_folder, episode_trigger=episode_trigger, step_trigger=step_trigger,
            video_length=video_length, name_prefix=name_prefix, fps=fps, overwrite=overwrite)
        gym.Wrapper.__init__(self, env)
        if env.render_mode != "rgb_array":
            raise InputError(f"RecordVideo needs render_mode='rgb_array' (frames as arrays), got {env.render_mode!r}")
        if episode_trigger is None and step_trigger is None:
            episode_trigger = capped_cubic_video_schedule
        if isinstance(video_length, bool) or not isinstance(video_length, int) or video_length < 0:
            raise InputError(f"RecordVideo: video_length must be an integer >= 0 (0 = whole episodes), got {video_length!r}")
        self.episode_trigger, self.step_trigger = episode_trigger, step_trigger
        self.video_folder = Path(video_folder)
        self.video_folder.mkdir(parents=True, exist_ok=True)
        self.fps = float(fps if fps is not None else self.metadata.get("render_fps", 30))
        self.video_length = video_length or math.inf
        self.name_prefix = name_prefix
        self.overwrite = overwrite
        self.episode_id = -1
        self.step_id = -1
        self._writer: VideoWriter | None = None
        self.videos: list[Path] = []
        """Paths of the videos written so far."""

    @property
    def recording(self) -> bool:
        return self._writer is not None

    def start_recording(self, name: str) -> None:
        self.stop_recording()
        self._writer = VideoWriter(self.video_folder / f"{name}.mp4", fps=self.fps, overwrite=self.overwrite)

    def stop_recording(self) -> None:
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.close()
            if writer.frames:
                self.videos.append(writer.path)

    def _capture(self) -> None:
        frame = self.env.render()
        if isinstance(frame, list):  # rgb_array_list envs
            frame = frame[-1] if frame else None
        if not isinstance(frame, np.ndarray):
            self.stop_recording()
            raise InputError(f"RecordVideo: env.render() returned {type(frame).__name__}, expected an RGB array")
        assert self._writer is not None
        self._writer.write(frame)
        if self._writer.frames >= self.video_length:
            self.stop_recording()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.episode_id += 1
        if self.recording and self.video_length == math.inf:
            self.stop_recording()
        if self.episode_trigger is not None and self.episode_trigger(self.episode_id):
            self.start_recording(f"{self.name_prefix}-episode-{self.episode_id}")
        if self.recording:
            self._capture()
        return obs, info

    def step(self, action):
        out = self.env.step(action)
        self.step_id += 1
        if self.step_trigger is not None and self.step_trigger(self.step_id):
            self.start_recording(f"{self.name_prefix}-step-{self.step_id}")
        if self.recording:
            self._capture()
        return out

    def close(self) -> None:
        self.stop_recording()
        super().close()
