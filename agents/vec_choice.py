"""Which vector env ``agents.train`` trains on: the batched ``RollingDriveVecEnv`` or a
``DummyVecEnv`` of single envs, whichever a short measurement at start finds faster."""

from __future__ import annotations

import time

from .common import (
    make_vec_env,
)

VEC_ENVS = ("batched", "dummy")  # the kinds of common.make_vec_env


def measure_vec_envs(
    scene, n_envs: int, env_kwargs, num_threads=None, seconds=1.0, rounds=3
) -> dict:
    """Env steps/s of each kind of training vector env (``VEC_ENVS``) here and now: random
    actions, timed passes of the kinds in turn (``rounds`` rounds, ``seconds`` in all), the
    best pass of each counting.  The batched env's own thread choice settles in the untimed
    warm-up."""
    import numpy as np

    acts = np.random.default_rng(0).uniform(-1, 1, (64, n_envs, 3)).astype(np.float32)
    envs = {
        k: make_vec_env(scene, n_envs, 0, env_kwargs, kind=k, num_threads=num_threads)
        for k in VEC_ENVS
    }
    best = dict.fromkeys(envs, 0.0)
    try:
        for env in envs.values():
            env.reset()
            for a in acts[:32]:
                env.step(a)
        span = seconds / (rounds * len(envs))
        for _ in range(rounds):
            for k, env in envs.items():
                steps, t0 = 0, time.perf_counter()
                while (t := time.perf_counter() - t0) < span:
                    env.step(acts[steps % len(acts)])
                    steps += 1
                best[k] = max(best[k], steps * n_envs / t)
    finally:
        for env in envs.values():
            env.close()
    return best


def choose_vec_env(
    flag: str, scene, n_envs: int, env_kwargs, num_threads=None, measure=measure_vec_envs
):
    """The training vector env's kind and what decided it: ``flag`` ("auto" or one of
    ``VEC_ENVS``); for "auto" the faster of ``measure(scene, n_envs, env_kwargs,
    num_threads)`` (env steps/s per kind).  Returns (kind, record for meta.json)."""
    if flag != "auto":
        return flag, {"kind": flag, "chosen_by": "--vec-env"}
    from rolling_env.env.scenes import load_scene

    kw = {k: v for k, v in dict(env_kwargs or {}).items() if k != "scene"}
    if load_scene(scene, **kw).randomize:  # the batched envs step one physics only
        return "dummy", {
            "kind": "dummy",
            "chosen_by": "the scene draws its physics per episode (randomize): single envs",
        }
    rates = measure(scene, n_envs, env_kwargs, num_threads)
    kind = max(VEC_ENVS, key=lambda k: rates[k])
    return kind, {
        "kind": kind,
        "chosen_by": "measured at start",
        "env_steps_per_s": {k: round(rates[k]) for k in VEC_ENVS},
    }
