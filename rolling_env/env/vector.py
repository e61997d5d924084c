"""Natively batched RollingDrive-v0: one compiled call steps N envs.

``BatchCore`` holds N envs' state with a leading env axis and steps them all in one call of the
env kernel (the same ``_envkernel`` tick the single env runs with a batch of one, so the
transitions are bit-identical to N single envs).  Two thin adapters:

* ``RollingDriveVectorEnv`` (``gymnasium.vector.VectorEnv``, NEXT_STEP autoreset), the
  ``vector_entry_point`` of ``gym.make_vec("RollingDrive-v0", num_envs=N)``;
* ``RollingDriveVecEnv`` (Stable-Baselines3 ``VecEnv``, same-step autoreset with
  ``terminal_observation`` and ``TimeLimit.truncated``), for training.  It lives in
  ``rolling_env.env.sb3_vec`` so that ``gym.make_vec`` imports neither Stable-Baselines3 nor torch;
  importing it from here still works (``__getattr__`` below).

Seeding follows Gymnasium: env i of a batch seeded s behaves like a single env seeded s + i.

Threads (``num_threads``).  Whether numba's threads pay depends on the host's load of the
moment, not on the batch alone: on a 2-vCPU VM the threaded kernel at 256 envs ran at 0.3x the
serial kernel one hour and 1.8x the next, because worker threads that wait (spinning, with
numba's OpenMP layer) between two steps compete with the Python thread and with other
processes for the cores.  So by default (``num_threads=None``) a ``ThreadPolicy`` picks the
path step by step from what it measures: it runs the faster of the serial kernel and the
threaded kernel (at 2, 4, ... up to the calling thread's numba thread count), and now and then
times a few steps of the others, the time from one step's start to the next, so that the
Python work between steps counts too.  The probes of a slower path are spaced so that they
cost at most ``ThreadPolicy.BUDGET`` of the time, and a larger thread count is not probed while
other processes leave too few of this process's cores idle (``rolling_env.env.hostload``, from
Linux's CPU counters over the caller's recent steps): on a busy host threads lose, and each
probe would cost a few slow steps.  Transitions are bit-identical on every path,
so switching changes no result.  ``num_threads=1`` always runs the serial kernel, ``k`` the
threaded kernel on k threads.  The thread count is set for each threaded step only and
restored after it (numba keeps it per calling thread); the threading layer and its wait policy
stay numba's (``NUMBA_THREADING_LAYER``, ``OMP_WAIT_POLICY``: nothing here sets them).  Below
``PARALLEL_MIN_ENVS`` envs the default runs the serial kernel only, set where the threads
paid little on the 2-core machine (docs/performance.md has the measurements).
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from rolling_env.env import _envkernel as EK
from rolling_env.env.drive_env import (
    OBS_NAMES,
    build_drive,
    check_action_dtype,
    check_actions,
    check_time_limit,
    info_arrays,
    info_dict,
    load_actions,
    raise_step_error,
    sample_target,
    target_option,
)
from rolling_env.env.hostload import HostLoad
from rolling_env.env.scenes import load_scene
from rolling_env.env.threads import (
    PARALLEL_MIN_ENVS,
    ThreadPolicy,
    _callers_threads,
    _kernel_for,
    check_num_threads,
    thread_choices,
)
from rolling_env.physics import _kernel as K
from rolling_env.physics.kernel_state import CellViews

__all__ = [
    "BatchCore",
    "RollingDriveVectorEnv",
    "RollingDriveVecEnv",  # noqa: F822 (module __getattr__ below)
    "make_vector_env",
    "PARALLEL_MIN_ENVS",
    "ThreadPolicy",
    "check_num_threads",
]


def _check_seed(seed, name: str) -> int:
    """A seed as a Python int: a non-negative integer (numpy integers too), not a bool."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer or None, got {seed!r}")
    return int(seed)


def _physical_memory() -> float:
    """Bytes of physical memory (inf where the OS does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return math.inf


def _check_memory(n: int, cell_bytes: int, scene) -> None:
    """A batch whose cell arrays alone exceed the machine's memory is a ValueError naming
    num_envs and the scene keys that size an env's cells (numpy's "Unable to allocate 7 PiB"
    named neither)."""
    need = float(n) * cell_bytes
    have = _physical_memory()
    if need > have:
        raise ValueError(
            f"num_envs = {n} envs x {cell_bytes / 2**20:.3g} MiB of cell state each "
            f"(resolution = {scene.resolution!r}, grid_levels = {scene.grid_levels!r}, "
            f"stroke_roll = {scene.stroke_roll!r}) need {need / 2**30:.3g} GiB, more than this "
            f"machine's {have / 2**30:.3g} GiB: lower num_envs, or the scene's resolution, "
            "grid_levels or stroke"
        )


class BatchCore(CellViews):
    """N envs of one scene: state arrays with a leading env axis, ``step``, ``reset(mask)``.

    ``num_threads``: None (default) picks the serial or the threaded kernel and its thread
    count step by step from measured step times (``ThreadPolicy``, ``thread_policy``); 1
    always runs the serial kernel; k in [2, NUMBA_NUM_THREADS] the threaded kernel on k
    threads.  ``threads`` says what the batch steps on now."""

    #: attributes holding one entry per env (leading axis num_envs); the rest is shared
    PER_ENV = frozenset(
        {
            "cells",
            "U",
            "A",
            "B",
            "L",
            "st",
            "p",
            "target",
            "steps",
            "act",
            "out",
            "obs",
            "extra",
            "rew",
            "trunc",
            "rngs",
        }
    )

    def __init__(
        self, num_envs: int, scene="default", max_episode_steps=None, num_threads=None, **overrides
    ):
        if (
            isinstance(num_envs, (bool, np.bool_))
            or not isinstance(num_envs, numbers.Integral)
            or num_envs < 1
        ):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        n = int(num_envs)
        self.num_threads = check_num_threads(num_threads)
        self.num_envs = n
        self.scene = load_scene(scene, **overrides)
        if self.scene.randomize:  # one compiled call steps one physics for the whole batch
            keys = ", ".join(k for k, _, _ in self.scene.randomize)
            raise ValueError(
                f"scene {self.scene.name!r} draws {keys} per episode (randomize): "
                "the batched envs step one physics for all envs; use single "
                "envs (gym.make, make_vec(..., vectorization_mode='sync'), SB3's "
                "DummyVecEnv: agents.train --vec-env dummy)"
            )
        self.max_episode_steps = check_time_limit(max_episode_steps, self.scene)
        drive, self.a_max = build_drive(self.scene)
        self.drive = drive  # template (grid, scales)
        self.features = drive.kernel_features + (None,)  # (mu, mass, load, ledger)
        self.sv = EK.scene_vector(self.scene, self.a_max, drive)
        _check_memory(n, drive.cells.nbytes, self.scene)
        self.cells = np.zeros((n,) + drive.cells.shape)  # per env: U, A, B (and L), see _kernel
        self.st = np.zeros((n, K.N_STATE))
        self.p = np.tile(drive._p, (n, 1))
        self.target = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.act = np.zeros((n, 3))
        self.out = np.zeros((n, K.N_OUT))
        self.obs = np.zeros((n, EK.N_OBS), dtype=np.float32)
        self.extra = np.zeros((n, EK.N_X))
        self.rew = np.zeros(n)  # written by the kernel: reward and steps >= max_episode_steps
        self.trunc = np.zeros(n, dtype=np.bool_)
        self.rngs = [seeding.np_random(None)[0] for _ in range(n)]
        self.thread_policy = None  # the ThreadPolicy when num_threads is None, else None
        if self.num_threads is not None:
            self._step_fn = _kernel_for(self.num_threads)
        else:
            # the caller's numba thread count caps the choices (asked only where threads may
            # run: it starts numba's thread pool)
            choices = (1,) if n < PARALLEL_MIN_ENVS else thread_choices(n, _callers_threads())
            if len(choices) == 1:
                self._step_fn = _kernel_for(choices[0])
            else:
                # probes only thread counts that the cores other processes leave idle hold
                self.thread_policy = self._step_fn = ThreadPolicy(choices, load=HostLoad())

    @property
    def threads(self) -> int:
        """Threads the batch steps on now (1: the serial kernel)."""
        if self.thread_policy is not None:
            return self.thread_policy.threads
        return self.num_threads or 1

    def seed(self, seed=None):
        """Env i gets seed + i (Gymnasium's convention); None draws fresh entropy.  A sequence
        of num_envs seeds (int or None each) seeds env i with seed[i] (None: left as is).
        Seeds are non-negative integers (numpy integers included); anything else raises."""
        if isinstance(seed, np.ndarray) and seed.ndim == 0:
            seed = seed.item()
        if isinstance(seed, (list, tuple, np.ndarray)):
            if len(seed) != self.num_envs:
                raise ValueError(
                    f"seed must be an int, None or a sequence of num_envs = "
                    f"{self.num_envs} seeds, got {len(seed)} seeds"
                )
            seeds = [
                None if s is None else _check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)
            ]
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
        if mask is not None:
            m = np.asarray(mask)
            if m.dtype != np.bool_ or m.shape != (self.num_envs,):
                raise ValueError(
                    f"mask must be None or a bool array of shape "
                    f"({self.num_envs},) (True: reset that env), got {mask!r}"
                )
        idx = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        # every env's options checked before any env changes: a bad one resets nothing
        given = self.check_options(options, idx)
        for i, g in zip(idx, given):  # each env draws from its own generator
            self.target[i] = sample_target(self.scene, self.rngs[i], g)
        self.cells[idx] = 0.0  # the scratch and level-grid rows too
        self.st[idx] = 0.0
        self.steps[idx] = 0
        self.extra[idx] = 0.0
        self.extra[idx, EK.X_SAT] = 1.0
        for i in idx:
            EK.reset_obs(i, self.sv, self.target, self.obs)

    def check_options(self, options, idx=None) -> list:
        """The target each env of ``idx`` (default all) asks for (None: draw one), checked:
        ``options`` is None, one dict for every env or a sequence of num_envs dicts (or
        None).  Raises before anything changes."""
        per_env = isinstance(options, (list, tuple, np.ndarray))
        if per_env and len(options) != self.num_envs:
            raise ValueError(
                f"options must be a dict or a sequence of num_envs = "
                f"{self.num_envs} dicts, got {len(options)}"
            )
        idx = range(self.num_envs) if idx is None else idx
        return [target_option(self.scene, options[i] if per_env else options) for i in idx]

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance every env one tick; returns (obs float32, rewards, truncated)."""
        a = load_actions(actions, (self.num_envs, 3), self.act)
        policy = self._step_fn if self._step_fn is self.thread_policy else None
        fn = self._step_fn if policy is None else policy.kernel()
        bad = fn(
            self.act,
            self.sv,
            self.target,
            self.steps,
            self.cells,
            self.st,
            self.p,
            self.out,
            self.obs,
            self.extra,
            self.rew,
            self.trunc,
            self.max_episode_steps,
            *self.features,
        )
        if policy is not None:
            policy.done()
        if bad:
            raise_step_error(bad, a, (self.num_envs, 3), self.st, self.scene, self.extra)
        return self.obs.copy(), self.rew.copy(), self.trunc.copy()

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
        self._not_reset = np.ones(self.num_envs, dtype=bool)  # never reset yet
        self._any_not_reset = True

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
        self._not_reset[slice(None) if mask is None else mask] = False
        self._any_not_reset = bool(self._not_reset.any())
        return self.core.obs.copy(), self._infos(mask)

    def _reset_mask(self, m) -> np.ndarray:
        if not (
            isinstance(m, np.ndarray)
            and m.dtype == np.bool_
            and m.shape == (self.num_envs,)
            and m.any()
        ):
            raise ValueError(
                f"options['reset_mask'] must be a numpy bool array of shape "
                f"({self.num_envs},) with at least one True, got {m!r}"
            )
        return m.copy()

    def step(self, actions):
        if self._any_not_reset:  # as gym.make's OrderEnforcing does for each env of "sync"
            from gymnasium.error import ResetNeeded

            raise ResetNeeded(
                f"Cannot call step() before reset(): env(s) "
                f"{np.flatnonzero(self._not_reset).tolist()[:10]} were never "
                "reset"
            )
        actions = check_action_dtype(actions)  # range and finiteness are checked by core.step
        if actions.shape != (self.num_envs, 3):  # before np.where below could broadcast it
            check_actions(actions, (self.num_envs, 3))  # raises naming the shape
        was_done = self._autoreset.copy()
        any_done = np.count_nonzero(was_done) > 0  # a quarter of the time of .any() here
        obs, rew, trunc = self.core.step(
            np.where(was_done[:, None], 0.0, actions) if any_done else actions
        )
        if any_done:
            self.core.reset(was_done)  # the envs that ended last step start over instead
            obs = self.core.obs.copy()
            rew[was_done] = 0.0
            trunc[was_done] = False
        term = np.zeros(self.num_envs, dtype=bool)  # the drive has no terminal state
        self._autoreset = trunc.copy()  # trunc | term; a copy: the caller may change trunc
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
        d.update(zip(_MASK_KEYS, masks, strict=True))
        return d


_MASK_KEYS = tuple("_" + k for k in info_arrays(np.zeros((1, EK.N_X)), np.zeros(1)))
