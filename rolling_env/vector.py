"""Natively batched RollingDrive-v0: one compiled call steps N envs.

``BatchCore`` holds N envs' state with a leading env axis and steps them all in one call of the
env kernel (the same ``_envkernel`` tick the single env runs with a batch of one, so the
transitions are bit-identical to N single envs).  Two thin adapters:

* ``RollingDriveVectorEnv`` (``gymnasium.vector.VectorEnv``, NEXT_STEP autoreset), the
  ``vector_entry_point`` of ``gym.make_vec("RollingDrive-v0", num_envs=N)``;
* ``RollingDriveVecEnv`` (Stable-Baselines3 ``VecEnv``, same-step autoreset with
  ``terminal_observation`` and ``TimeLimit.truncated``), for training.

Seeding follows Gymnasium: env i of a batch seeded s behaves like a single env seeded s + i.
The threaded kernel (``prange``) is used from ``PARALLEL_MIN_ENVS`` envs on: measured on the
2-core machine (default scene, ``rolling-drive bench``, results/benchmarks.md) it is 0.8-0.9x
the serial kernel at 1 env, 1.0-1.2x at 2 (within the spread between runs), 1.2-1.4x at 4 and
1.9-2.3x at 64-256, where the second core gives about 2x (the serial kernel has caught up
with the prange kernel's generated code on one thread since its cell loops use unsigned
indices).
"""
from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from . import _envkernel as EK
from . import _kernel as K
from .env import (OBS_NAMES, build_drive, check_action_dtype, check_actions, check_time_limit,
                  info_arrays, info_dict, load_actions, raise_step_error, sample_target,
                  target_option)
from .scenes import load_scene

PARALLEL_MIN_ENVS = 4


def _check_seed(seed, name: str) -> int:
    """A seed as a Python int: a non-negative integer (numpy integers too), not a bool."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer or None, got {seed!r}")
    return int(seed)


class BatchCore:
    """N envs of one scene: state arrays with a leading env axis, ``step``, ``reset(mask)``."""

    #: attributes holding one entry per env (leading axis num_envs); the rest is shared
    PER_ENV = frozenset({"U", "A", "B", "L", "st", "p", "target", "steps", "act", "out",
                         "obs", "extra", "rngs"})

    def __init__(self, num_envs: int, scene="default", max_episode_steps=None, **overrides):
        if (isinstance(num_envs, (bool, np.bool_)) or not isinstance(num_envs, numbers.Integral)
                or num_envs < 1):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        n = int(num_envs)
        self.num_envs = n
        self.scene = load_scene(scene, **overrides)
        self.max_episode_steps = check_time_limit(max_episode_steps, self.scene)
        drive, self.a_max = build_drive(self.scene)
        self.drive = drive  # template (grid, scales)
        self.features = drive.kernel_features + (None,)  # (mu, mass, load, ledger)
        self.sv = EK.scene_vector(self.scene, self.a_max, drive)
        m = drive.grid.n
        self.U = np.zeros((n, m))
        self.A = np.zeros((n, m))
        self.B = np.zeros((n, m))
        self.L = np.zeros((n,) + drive.L.shape)
        self.st = np.zeros((n, K.N_STATE))
        self.p = np.tile(drive._p, (n, 1))
        self.target = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.act = np.zeros((n, 3))
        self.out = np.zeros((n, K.N_OUT))
        self.obs = np.zeros((n, EK.N_OBS), dtype=np.float32)
        self.extra = np.zeros((n, EK.N_X))
        self.rngs = [seeding.np_random(None)[0] for _ in range(n)]
        self._step_fn = EK.env_step_parallel if n >= PARALLEL_MIN_ENVS else EK.env_step_serial

    def seed(self, seed=None):
        """Env i gets seed + i (Gymnasium's convention); None draws fresh entropy.  A sequence
        of num_envs seeds (int or None each) seeds env i with seed[i] (None: left as is).
        Seeds are non-negative integers (numpy integers included); anything else raises."""
        if isinstance(seed, np.ndarray) and seed.ndim == 0:
            seed = seed.item()
        if isinstance(seed, (list, tuple, np.ndarray)):
            if len(seed) != self.num_envs:
                raise ValueError(f"seed must be an int, None or a sequence of num_envs = "
                                 f"{self.num_envs} seeds, got {len(seed)} seeds")
            seeds = [None if s is None else _check_seed(s, f"seed[{i}]")
                     for i, s in enumerate(seed)]
            for i, s in enumerate(seeds):
                if s is not None:
                    self.rngs[i] = seeding.np_random(s)[0]
            return
        base = None if seed is None else _check_seed(seed, "seed")
        for i in range(self.num_envs):
            self.rngs[i] = seeding.np_random(None if base is None else base + i)[0]

    def reset(self, mask=None, options=None) -> None:
        """Reset the envs where ``mask`` is True (all when None).  ``options``: one dict for
        every env, or a sequence of num_envs dicts (or None), one per env."""
        idx = range(self.num_envs) if mask is None else np.flatnonzero(mask)
        # every env's options checked before any env changes: a bad one resets nothing
        given = self.check_options(options, idx)
        for i, g in zip(idx, given):
            self.target[i] = sample_target(self.scene, self.rngs[i], g)
            self.U[i] = 0.0
            self.st[i] = 0.0
            self.steps[i] = 0
            self.extra[i] = 0.0
            self.extra[i, EK.X_SAT] = 1.0
            EK.reset_obs(i, self.sv, self.target, self.obs)

    def check_options(self, options, idx=None) -> list:
        """The target each env of ``idx`` (default all) asks for (None: draw one), checked:
        ``options`` is None, one dict for every env or a sequence of num_envs dicts (or
        None).  Raises before anything changes."""
        per_env = isinstance(options, (list, tuple, np.ndarray))
        if per_env and len(options) != self.num_envs:
            raise ValueError(f"options must be a dict or a sequence of num_envs = "
                             f"{self.num_envs} dicts, got {len(options)}")
        idx = range(self.num_envs) if idx is None else idx
        return [target_option(self.scene, options[i] if per_env else options) for i in idx]

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance every env one tick; returns (obs float32, rewards, truncated)."""
        a = load_actions(actions, (self.num_envs, 3), self.act)
        bad = self._step_fn(self.act, self.sv, self.target, self.steps, self.U, self.A, self.B,
                            self.L, self.st, self.p, self.out, self.obs, self.extra,
                            *self.features)
        if bad:
            raise_step_error(bad, a, (self.num_envs, 3), self.st)
        return self.obs.copy(), self.extra[:, EK.X_REWARD].copy(), \
            self.steps >= self.max_episode_steps

    def info(self, i: int) -> dict:
        return info_dict(self.extra[i], self.target[i])

    def observation_space(self):
        return spaces.Box(-EK.OBS_BOUND, EK.OBS_BOUND, (len(OBS_NAMES),), np.float32)


# ----------------------------------------------------------------------------- Gymnasium
def make_vector_env(num_envs: int = 1, max_episode_steps=None, **kwargs):
    """``vector_entry_point`` of RollingDrive-v0 (``gym.make_vec(..., num_envs=N)``)."""
    return RollingDriveVectorEnv(num_envs, max_episode_steps=max_episode_steps, **kwargs)


def _gym_vector_base():
    from gymnasium.vector import VectorEnv
    return VectorEnv


class RollingDriveVectorEnv(_gym_vector_base()):
    """Gymnasium vector env over ``BatchCore`` with NEXT_STEP autoreset: the step after an
    episode ends resets that env and returns its first observation, reward 0 and no flags."""

    def __init__(self, num_envs: int = 1, max_episode_steps=None, render_mode=None, **kwargs):
        from gymnasium.vector import AutoresetMode
        from gymnasium.vector.utils import batch_space

        if render_mode is not None:
            raise ValueError("the batched env does not render; use a single env to look at it")
        self.core = BatchCore(num_envs, max_episode_steps=max_episode_steps, **kwargs)
        self.num_envs = self.core.num_envs
        self.metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
        self.render_mode = None
        self.single_observation_space = self.core.observation_space()
        self.single_action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed=None, options=None):
        """Reset every env, or with ``options={"reset_mask": m}`` (a bool array, one entry per
        env, as Gymnasium's own vector envs take it) only those where m is True: seeds apply
        to them only, and the infos' ``_key`` masks are m.  Seeds and options are checked
        before anything changes."""
        mask = None
        if isinstance(options, Mapping) and "reset_mask" in options:
            options = dict(options)  # the caller's dict is left as it was
            mask = self._reset_mask(options.pop("reset_mask"))
            options = options or None
        self.core.check_options(options, None if mask is None else np.flatnonzero(mask))
        if seed is not None:
            if mask is not None:
                if isinstance(seed, np.ndarray) and seed.ndim == 0:
                    seed = seed.item()
                if isinstance(seed, numbers.Integral) and not isinstance(seed, (bool, np.bool_)):
                    seed = [int(seed) + i for i in range(self.num_envs)]
                if isinstance(seed, (list, tuple, np.ndarray)) and len(seed) == self.num_envs:
                    seed = [s if m else None for s, m in zip(seed, mask)]
            self.core.seed(seed)  # int: env i gets seed + i; or one seed (or None) per env
            if isinstance(seed, numbers.Integral):
                self.action_space.seed(int(seed))
        self.core.reset(mask, options)
        self._autoreset[slice(None) if mask is None else mask] = False
        return self.core.obs.copy(), self._infos(mask)

    def _reset_mask(self, m) -> np.ndarray:
        if not (isinstance(m, np.ndarray) and m.dtype == np.bool_ and m.shape == (self.num_envs,)
                and m.any()):
            raise ValueError(f"options['reset_mask'] must be a numpy bool array of shape "
                             f"({self.num_envs},) with at least one True, got {m!r}")
        return m.copy()

    def step(self, actions):
        actions = check_action_dtype(actions)  # range and finiteness are checked by core.step
        if actions.shape != (self.num_envs, 3):  # before np.where below could broadcast it
            check_actions(actions, (self.num_envs, 3))  # raises naming the shape
        was_done = self._autoreset.copy()
        obs, rew, trunc = self.core.step(np.where(was_done[:, None], 0.0, actions)
                                         if was_done.any() else actions)
        if was_done.any():
            self.core.reset(was_done)  # the envs that ended last step start over instead
            self.core.steps[was_done] = 0
            obs = self.core.obs.copy()
            rew[was_done] = 0.0
            trunc[was_done] = False
        term = np.zeros(self.num_envs, dtype=bool)
        self._autoreset = trunc | term
        return obs, rew, term, trunc, self._infos()

    def _infos(self, mask=None) -> dict:
        """The single env's info keys as arrays with Gymnasium's ``_key`` masks (every env
        reports each key, or those of ``mask``; an env reset this step reports its reset info,
        as in "sync")."""
        d = info_arrays(self.core.extra, self.core.target)
        masks = np.ones((len(d), self.num_envs), dtype=bool)  # one allocation, rows as views
        if mask is not None:
            masks[:] = mask
            for v in d.values():
                v[~mask] = 0  # Gymnasium's fill for envs without info
        d.update(zip(["_" + k for k in d], masks))
        return d


# ----------------------------------------------------------------------------- Stable-Baselines3
def _sb3_vecenv_base():
    from stable_baselines3.common.vec_env import VecEnv
    return VecEnv


class RollingDriveVecEnv(_sb3_vecenv_base()):
    """SB3 ``VecEnv`` over ``BatchCore``: same-step autoreset; a finished env's last observation
    is ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]`` is
    ``truncated and not terminated``.  Wrap with ``VecMonitor`` for episode statistics.
    Infos carry the reward terms of every env; the terminal keys only for those that ended."""

    def __init__(self, num_envs: int = 1, scene="default", max_episode_steps=None,
                 render_mode=None, **overrides):
        if render_mode is not None:
            raise ValueError("render_mode must be None: the batched env does not render; use "
                             "a single env (rolling_env.make(..., render_mode='rgb_array'))")
        self.core = BatchCore(num_envs, scene=scene, max_episode_steps=max_episode_steps,
                              **overrides)
        self.render_mode = None  # set before the base class reads it
        super().__init__(self.core.num_envs, self.core.observation_space(),
                         spaces.Box(-1.0, 1.0, (3,), np.float32))
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
        infos = [{"reward_track": tr, "reward_wear": we} for tr, we in
                 zip(x[:, EK.X_TRACK].tolist(), x[:, EK.X_WEAR].tolist())]
        if trunc.any():
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
            raise AttributeError(f"{attr_name!r} is per-env physics state, read-only (reset the "
                                 "env to start it over); writable per env: "
                                 f"{sorted(self.PER_ENV_WRITABLE)}, shared: "
                                 f"{sorted(self.SHARED_WRITABLE)}")
        if attr_name == "max_episode_steps":
            value = check_time_limit(value, self.core.scene)
        elif attr_name == "target":  # the same check as reset(options={"target": ...})
            value = target_option(self.core.scene, {"target": value})
        elif attr_name == "steps":  # ticks into the episode: the env truncates at the limit
            limit = self.core.max_episode_steps
            if (isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral)
                    or not 0 <= value < limit):
                raise ValueError(f"steps must be an integer in [0, {limit - 1}] (ticks into the "
                                 f"episode, below max_episode_steps = {limit}), got {value!r}")
            value = int(value)
        elif attr_name == "rngs":  # the env's random generator (reset draws targets from it)
            if not isinstance(value, np.random.Generator):
                raise ValueError("rngs must be a numpy.random.Generator (e.g. "
                                 "numpy.random.default_rng(seed); or use seed()), got "
                                 f"{type(value).__name__}")
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
            raise AttributeError(f"{attr_name!r} is fixed when the batch is built (make a new "
                                 f"env to change it); writable: {sorted(self.SHARED_WRITABLE)} "
                                 f"and per env {sorted(self.PER_ENV_WRITABLE)}")
        elif sorted(idx) == list(range(self.num_envs)):
            setattr(self.core, attr_name, value)
        else:
            raise NotImplementedError(f"{attr_name!r} is shared by every env of the batch; "
                                      "set it for all envs (indices=None)")

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
            raise NotImplementedError(f"BatchCore.{method_name} acts on the whole batch; call "
                                      "it for all envs (indices=None)")
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
