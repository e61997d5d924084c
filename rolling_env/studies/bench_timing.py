"""Timing helpers of the benchmarks: interleaved passes whose best counts, so that a burst of
the shared host's load hits every entry a ratio compares alike, and the passes of a single
env, a batched core and a vector env."""

from __future__ import annotations

import math
import time

import numpy as np

ROUNDS = 3  # rounds of interleaved timed passes; each entry's best pass counts


def _best_rates(passes: dict, rounds=ROUNDS) -> dict:
    """Best rate of each named timed pass (a function that runs once and returns its rate),
    the passes taken in turn for ``rounds`` rounds.  Interleaved so that the entries a ratio
    compares see the same stretch of the shared host's load: timed one after the other, a
    burst during one entry's passes skewed the ratio (a single env measured 35% slow gave the
    batched env 13.9x instead of 8-9x in one run)."""
    best = dict.fromkeys(passes, 0.0)
    for _ in range(rounds):
        for name, run_pass in passes.items():
            best[name] = max(best[name], run_pass())
    return best


def _interleaved_rates(runs: dict, total: int, segment: int) -> dict:
    """Env steps/s of each entry, the entries run in turn in segments of ``segment`` steps
    until each has made ``total``: every entry meets the same stretches of the host's load,
    and the rate counts all its steps (a choice made at run time pays for its probes).  On
    a shared host whose load changes within seconds, the best passes of whole rounds gave
    two entries running the same kernel rates 2x apart.  The order changes each round
    (``_orders``), and each segment is followed by an untimed pause (``SEGMENT_PAUSE``).
    ``runs[name](k)`` makes the next
    k steps and returns the env steps made."""
    spent = dict.fromkeys(runs, 0.0)
    made = dict.fromkeys(runs, 0)
    orders = _orders(runs)
    for r, start in enumerate(range(0, total, segment)):
        k = min(segment, total - start)
        for name in orders[r % len(orders)]:
            t = time.perf_counter()
            made[name] += runs[name](k)
            spent[name] += time.perf_counter() - t
            time.sleep(SEGMENT_PAUSE)
    return {name: made[name] / spent[name] for name in runs}


# untimed pause after each segment: OpenMP's worker threads spin for some milliseconds after
# a threaded step, and would slow the next entry's first steps (a neighbour that a user's
# single env does not have); the order of the entries changes each round as well
SEGMENT_PAUSE = 0.05


def _orders(names) -> list:
    """The orders in which ``_interleaved_rates`` takes the entries, round after round:
    every permutation in turn, so that each entry follows each other one equally often."""
    import itertools

    return list(itertools.permutations(names))


def _segment(n_envs: int) -> int:
    """Steps of one segment for ``_interleaved_rates``: about 16k env steps (0.1-0.3 s
    here), long beside the switch from one entry to the next."""
    return max(16, 16_384 // n_envs)


def _env_pass(env, n, seed=0):
    """Timed pass of a single env: n steps of pre-sampled actions (resetting at episode
    ends), after a warm-up; returns steps/s per call."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (n, 3)).astype(np.float32)
    env.reset(seed=seed)
    for a in acts[: min(1000, n)]:
        env.step(a)

    def run_pass():
        t = time.perf_counter()
        for a in acts:
            _, _, te, tr, _ = env.step(a)
            if te or tr:
                env.reset()
        return n / (time.perf_counter() - t)

    return run_pass


def _core_pass(core, ticks, seed=0):
    """Timed pass of a BatchCore on random actions (truncated envs reset as they end), after a
    warm-up; returns (env steps/s, cell updates/s) per call."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, core.num_envs, 3))
    sc = core.scene
    N = sc.N_min + 0.5 * (acts[..., 0] + 1) * (sc.N_max - sc.N_min)
    d = (3 * N / (4 * sc.E_star * math.sqrt(sc.R))) ** (2 / 3)
    cells = float(np.sum(2 * np.sqrt(sc.R * d) / (core.a_max / sc.resolution) + 2))
    core.seed(seed)
    core.reset()
    for a in acts[:20]:
        core.step(a)

    def run_pass():
        t = time.perf_counter()
        for a in acts:
            _, _, tr = core.step(a)
            if np.count_nonzero(tr):  # a quarter of the time of tr.any() for 256 envs
                core.reset(tr)
        dt = time.perf_counter() - t
        return ticks * core.num_envs / dt, cells * sc.n_sub / dt

    return run_pass


def _core_runner(core, ticks, seed=0):
    """A BatchCore's steps in segments (for ``_interleaved_rates``): ``run(k)`` makes the next
    k ticks of ``ticks`` random actions taken in a cycle (truncated envs reset as they end),
    after a warm-up."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, core.num_envs, 3))
    core.seed(seed)
    core.reset()
    for a in acts[:20]:
        core.step(a)
    at = [0]

    def run(k):
        for _ in range(k):
            _, _, tr = core.step(acts[at[0]])
            if np.count_nonzero(tr):
                core.reset(tr)
            at[0] = (at[0] + 1) % ticks
        return k * core.num_envs

    return run


def _steps(run_pass):
    """The env steps/s of a ``_core_pass`` (for ``_best_rates``)."""
    return lambda: run_pass()[0]


def _vec_pass(step, n_envs, ticks, seed=0, between=None):
    """Timed pass of a vector env adapter (``step(actions)``), after a warm-up; returns
    aggregate env steps/s per call.  ``between``: work of the calling thread after each step
    (called with the step's result)."""
    acts = np.random.default_rng(seed).uniform(-1, 1, (ticks, n_envs, 3)).astype(np.float32)
    for a in acts[:20]:
        step(a)

    def run_pass():
        t = time.perf_counter()
        if between is None:
            for a in acts:
                step(a)
        else:
            for a in acts:
                between(step(a))
        return ticks * n_envs / (time.perf_counter() - t)

    return run_pass


TOP_ROUNDS = 5  # rounds for the batched-vs-single table (the headline ratio)


def _whole_episodes(ticks: int, episode: int) -> int:
    """``ticks`` rounded up to whole episodes: a timed pass of a batched env then holds its
    resets at the rate training meets them (each env resets once per ``episode`` ticks), as
    the single env's pass of many episodes does.  A pass shorter than an episode holds all
    the envs' resets or none, and the best of several passes picks one without them (3% of
    the batched env's steps/s at 256 envs before its reset was vectorised)."""
    return episode * max(1, -(-ticks // episode))
