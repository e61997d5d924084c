"""rolling-drive: MDR simulation and control of the oscillating-rolling nanodrive.

``import rolling_env`` registers ``RollingDrive-v0`` with Gymnasium.
"""

from __future__ import annotations

import gymnasium as gym

__version__ = "0.1.0"

if "RollingDrive-v0" not in gym.registry:
    gym.register(
        id="RollingDrive-v0",
        entry_point="rolling_env.env.drive_env:RollingDriveEnv",
        vector_entry_point="rolling_env.env.vector:make_vector_env",
        # no TimeLimit here: the env truncates at its scene's episode_steps (a TimeLimit from
        # gym.make(..., max_episode_steps=n) can only end episodes earlier)
    )


def make(scene="default", **kwargs):
    """``gym.make("RollingDrive-v0", scene=..., **overrides)`` with the scene loaded (and
    checked) first."""
    from rolling_env.env.scenes import load_scene

    sc = load_scene(scene, **{k: v for k, v in kwargs.items() if k not in _MAKE_KEYS})
    extra = {k: v for k, v in kwargs.items() if k in _MAKE_KEYS}
    from rolling_env.env.drive_env import check_time_limit

    if extra.get("max_episode_steps") is not None:
        extra["max_episode_steps"] = check_time_limit(extra["max_episode_steps"], sc)
    return gym.make("RollingDrive-v0", scene=sc, **extra)


_MAKE_KEYS = ("render_mode", "max_episode_steps", "disable_env_checker")


def list_scenes():
    from rolling_env.env.scenes import list_scenes as _ls

    return _ls()
