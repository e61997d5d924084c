"""Stable-Baselines3 adapter of the batched RollingDrive-v0 (``RollingDriveVecEnv``).

Kept apart from ``rolling_env.env.vector`` so that ``gym.make_vec("RollingDrive-v0")`` does not
import Stable-Baselines3 and torch: this module imports ``vector``, never the other way.
"""

from __future__ import annotations

import numbers

import numpy as np
from gymnasium import spaces

from rolling_env.env import _envkernel as EK
from rolling_env.env.drive_env import check_time_limit, target_option
from rolling_env.env.vector import BatchCore, _check_seed


def _sb3_vecenv_base():
    from stable_baselines3.common.vec_env import VecEnv

    return VecEnv


class RollingDriveVecEnv(_sb3_vecenv_base()):
    """SB3 ``VecEnv`` over ``BatchCore``: same-step autoreset; a finished env's last observation
    is ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]`` is
    ``truncated and not terminated``.  Wrap with ``VecMonitor`` for episode statistics.
    Infos carry the reward terms of every env; the terminal keys only for those that ended."""

    def __init__(
        self,
        num_envs: int = 1,
        scene="default",
        max_episode_steps=None,
        render_mode=None,
        num_threads=None,
        **overrides,
    ):
        if render_mode is not None:
            raise ValueError(
                "render_mode must be None: the batched env does not render; use "
                "a single env (rolling_env.make(..., render_mode='rgb_array'))"
            )
        # num_threads: None picks serial or threaded steps from measured step times, 1 the
        # serial kernel, k the threaded kernel on k threads (see rolling_env.env.vector)
        self.core = BatchCore(
            num_envs,
            scene=scene,
            max_episode_steps=max_episode_steps,
            num_threads=num_threads,
            **overrides,
        )
        self.render_mode = None  # set before the base class reads it
        super().__init__(
            self.core.num_envs,
            self.core.observation_space(),
            spaces.Box(-1.0, 1.0, (3,), np.float32),
        )
        self._actions = None

    def reset(self):
        options = [o or None for o in self._options]
        self.core.check_options(options)  # before the seeds change anything
        self.core.seed(list(self._seeds))
        self.core.reset(None, options)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [self.core.info(i) for i in range(self.num_envs)]
        return self.core.obs.copy()

    def step_async(self, actions):
        self._actions = actions

    def step_wait(self):
        obs, rew, trunc = self.core.step(self._actions)
        x = self.core.extra
        infos = [
            {"reward_track": tr, "reward_wear": we, "reward_final": fi}
            for tr, we, fi in zip(
                x[:, EK.X_TRACK].tolist(), x[:, EK.X_WEAR].tolist(), x[:, EK.X_FINAL].tolist()
            )
        ]
        if np.count_nonzero(trunc):  # a quarter of the time of trunc.any() for 256 envs
            ended = np.flatnonzero(trunc)
            for i in ended:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = True
            self.core.reset(trunc)
            obs = self.core.obs.copy()
        return obs, rew.astype(np.float32), trunc.copy(), infos

    def close(self):
        pass

    # Attributes and methods live on the batch (``BatchCore``).  Its per-env state
    # (``BatchCore.PER_ENV``: ``target``, ``steps``, ``rngs``, ...) is read and written per
    # index; anything else is shared by the batch and read for every index; of the shared
    # attributes only ``SHARED_WRITABLE`` can be written, for all envs at once (the scene,
    # its kernel constants and the batch size are fixed at construction).  Of the per-env
    # state only ``PER_ENV_WRITABLE`` can be written, each value checked: the physics state
    # (spring row, runner, observation, ...) is what the kernel made of the actions, and a
    # written value would be a state no episode reaches (reset the env to start over).
    SHARED_WRITABLE = frozenset({"max_episode_steps"})
    PER_ENV_WRITABLE = frozenset({"target", "steps", "rngs"})

    def _per_env(self, attr_name) -> bool:
        return attr_name in BatchCore.PER_ENV

    def get_attr(self, attr_name, indices=None):
        idx = list(self._get_indices(indices))
        if attr_name == "render_mode":
            return [None for _ in idx]
        if not hasattr(self.core, attr_name):
            raise AttributeError(f"RollingDriveVecEnv has no attribute {attr_name!r}")
        value = getattr(self.core, attr_name)
        if self._per_env(attr_name):
            return [value[i] for i in idx]
        return [value for _ in idx]

    def set_attr(self, attr_name, value, indices=None):
        if not hasattr(self.core, attr_name):
            raise AttributeError(f"RollingDriveVecEnv has no attribute {attr_name!r}")
        idx = list(self._get_indices(indices))
        if self._per_env(attr_name) and attr_name not in self.PER_ENV_WRITABLE:
            raise AttributeError(
                f"{attr_name!r} is per-env physics state, read-only (reset the "
                "env to start it over); writable per env: "
                f"{sorted(self.PER_ENV_WRITABLE)}, shared: "
                f"{sorted(self.SHARED_WRITABLE)}"
            )
        if attr_name == "max_episode_steps":
            value = check_time_limit(value, self.core.scene)
        elif attr_name == "target":  # the same check as reset(options={"target": ...})
            value = target_option(self.core.scene, {"target": value}, name="target")
        elif attr_name == "steps":  # ticks into the episode: the env truncates at the limit
            limit = self.core.max_episode_steps
            if (
                isinstance(value, (bool, np.bool_))
                or not isinstance(value, numbers.Integral)
                or not 0 <= value < limit
            ):
                raise ValueError(
                    f"steps must be an integer in [0, {limit - 1}] (ticks into the "
                    f"episode, below max_episode_steps = {limit}), got {value!r}"
                )
            value = int(value)
        elif attr_name == "rngs":  # the env's random generator (reset draws targets from it)
            if not isinstance(value, np.random.Generator):
                raise ValueError(
                    "rngs must be a numpy.random.Generator (e.g. "
                    "numpy.random.default_rng(seed); or use seed()), got "
                    f"{type(value).__name__}"
                )
        if self._per_env(attr_name):
            target = getattr(self.core, attr_name)
            if isinstance(target, list):
                for i in idx:
                    target[i] = value
            else:
                target[idx] = value
        elif attr_name not in self.SHARED_WRITABLE:
            # the scene, its kernel constants and the array sizes are fixed at construction:
            # setting them would leave the physics on the old values (or the arrays too short)
            raise AttributeError(
                f"{attr_name!r} is fixed when the batch is built (make a new "
                f"env to change it); writable: {sorted(self.SHARED_WRITABLE)} "
                f"and per env {sorted(self.PER_ENV_WRITABLE)}"
            )
        elif sorted(idx) == list(range(self.num_envs)):
            setattr(self.core, attr_name, value)
        else:
            raise NotImplementedError(
                f"{attr_name!r} is shared by every env of the batch; "
                "set it for all envs (indices=None)"
            )

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        """Call a ``BatchCore`` method once for the batch.  ``reset`` acts as the single env's
        ``reset(seed=None, options=None)`` on the envs of ``indices`` and returns their
        ``(obs, info)`` (as DummyVecEnv does); another method with a ``mask`` argument gets the
        mask of ``indices``; others need every env (indices=None)."""
        import inspect

        idx = list(self._get_indices(indices))
        if method_name == "reset":
            return self._reset_envs(idx, *method_args, **method_kwargs)
        fn = getattr(self.core, method_name)
        if "mask" in inspect.signature(fn).parameters:
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[idx] = True
            result = fn(*method_args, mask=mask, **method_kwargs)
        elif sorted(idx) == list(range(self.num_envs)):
            result = fn(*method_args, **method_kwargs)
        else:
            raise NotImplementedError(
                f"BatchCore.{method_name} acts on the whole batch; call "
                "it for all envs (indices=None)"
            )
        return [result for _ in idx]

    def _reset_envs(self, idx, seed=None, options=None) -> list:
        """``env.reset(seed=seed, options=options)`` of each env in ``idx`` (every one seeded
        ``seed``, as DummyVecEnv's env_method does); returns one ``(obs, info)`` per env."""
        mask = np.zeros(self.num_envs, dtype=bool)
        mask[idx] = True
        self.core.check_options(options, np.flatnonzero(mask))  # before the seeds change
        if seed is not None:
            s = _check_seed(seed, "seed")
            self.core.seed([s if m else None for m in mask])
        self.core.reset(mask, options)
        return [(self.core.obs[i].copy(), self.core.info(i)) for i in idx]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._get_indices(indices)]
