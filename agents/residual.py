"""Residual agents: a policy whose action is added to an Eq. 32 baseline's action.

The executed action is ``clip(a_base + scale * clip(a_policy, -1, 1), -1, 1)``, so a policy that
outputs zero is the baseline itself, and ``scale`` bounds how far the policy can move away
from it.  The policy sees the env's 13 observations followed by the baseline's action for the
same tick (16 numbers): the baseline is stateful (it re-plans once per excitation period), and
its action tells the policy what it is about to correct.

Training wraps the vector env in ``ResidualVecEnv`` (``agents.train`` does so when the
hyper-parameter entry has ``residual: <base>`` or with ``--residual <base>``); evaluation and
``rolling-drive rollout`` wrap the loaded policy in ``ResidualAgent`` (``loading.load_agent``
does so from the run's config.yml).  The baseline is built from the scene the run was trained
on, so on a held-out variant of a scene the baseline part knows what the agent knows.
"""

from __future__ import annotations

import copy

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

from .baselines import Eq32Feedback, Eq32OpenLoop, scene_of

#: the baselines a residual policy can be built on
BASES = {"eq32-feedback": Eq32Feedback, "eq32-open-loop": Eq32OpenLoop}
SCALE_DEFAULT = 0.25  # the policy moves each action by at most a quarter of its range
N_BASE = 3  # numbers the baseline's action adds to the observation


def check_residual(base, scale) -> tuple[str, float]:
    """(base, scale) checked: base one of ``BASES``, scale a number in (0, 2]; a ValueError
    naming the parameter otherwise."""
    if base not in BASES:
        raise ValueError(f"residual must be one of {sorted(BASES)}, got {base!r}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale <= 2:
        raise ValueError(f"residual_scale must be a number in (0, 2], got {scale!r}")
    return base, float(scale)


def combine(base_action, policy_action, scale: float) -> np.ndarray:
    """The executed action: the baseline's plus ``scale`` times the policy's (each clipped to
    the action box)."""
    r = np.clip(np.asarray(policy_action, dtype=np.float64), -1.0, 1.0)
    a = np.asarray(base_action, dtype=np.float64) + scale * r
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def augment(obs, base_action) -> np.ndarray:
    """The policy's observation: the env's followed by the baseline's action."""
    return np.concatenate(
        [np.asarray(obs, dtype=np.float32), np.asarray(base_action, dtype=np.float32)], axis=-1
    )


def augmented_space(space):
    """The observation space of ``augment``ed observations."""
    from gymnasium import spaces

    low = np.concatenate([space.low, -np.ones(N_BASE, np.float32)]).astype(np.float32)
    high = np.concatenate([space.high, np.ones(N_BASE, np.float32)]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


class ResidualVecEnv(VecEnvWrapper):
    """SB3 VecEnv wrapper: actions are residuals on ``base`` (built from the wrapped env's
    scene), observations carry the baseline's action (``augment``).  A finished env's
    ``terminal_observation`` is augmented with the action the baseline would take there,
    computed on a copy of the baseline so that its plan is not disturbed."""

    def __init__(self, venv, base: str = "eq32-feedback", scale: float = SCALE_DEFAULT):
        self.base, self.scale = check_residual(base, scale)
        self.controller = BASES[self.base](scene_of(venv))
        super().__init__(venv, observation_space=augmented_space(venv.observation_space))
        self._base_action = np.zeros((venv.num_envs, N_BASE), np.float32)

    def reset(self):
        obs = self.venv.reset()
        self._base_action, _ = self.controller.predict(
            obs, episode_start=np.ones(self.num_envs, bool)
        )
        return augment(obs, self._base_action)

    def step_async(self, actions):
        self.venv.step_async(combine(self._base_action, actions, self.scale))

    def step_wait(self):
        obs, rew, done, infos = self.venv.step_wait()
        ended = [i for i in np.flatnonzero(done) if "terminal_observation" in infos[i]]
        if ended:  # one copy of the baseline goes on from the last tick for every ended env
            rows = np.array(obs, dtype=np.float64)
            for i in ended:
                rows[i] = infos[i]["terminal_observation"]
            act, _ = copy.deepcopy(self.controller).predict(
                rows, episode_start=np.zeros(self.num_envs, bool)
            )
            for i in ended:
                infos[i]["terminal_observation"] = augment(infos[i]["terminal_observation"], act[i])
        self._base_action, _ = self.controller.predict(obs, episode_start=np.asarray(done))
        return augment(obs, self._base_action), rew, done, infos


class ResidualAgent:
    """A loaded residual policy (any object with SB3's ``predict``, observation statistics
    applied) acting with its baseline: ``predict`` takes the env's observations (one or a
    batch) and returns the executed actions."""

    def __init__(self, policy, base: str, scale: float, scene):
        self.base, self.scale = check_residual(base, scale)
        self.policy = policy
        self.controller = BASES[self.base](scene_of(scene))

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs, dtype=np.float32)
        b, _ = self.controller.predict(obs, episode_start=episode_start)
        r, state = self.policy.predict(
            augment(obs, b), state=state, episode_start=episode_start, deterministic=deterministic
        )
        return combine(b, r, self.scale), state
