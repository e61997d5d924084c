"""Record env trajectories as a regression reference for tests/test_kernel_paths.py.

    python tests/make_golden.py tests/data/golden_3ab498b.npz

The committed file was recorded with commit 3ab498b (the kernel before the 2026-11-24 speed-ups:
reference counting on, the edge cells walked piece by piece with the ledger off too, sin/cos of
the observation clock, pow for the Hertz indentation), checked out in a git worktree and run as
``PYTHONPATH=<worktree> NUMBA_CACHE_DIR=<empty dir> python tests/make_golden.py OUT``.  Later
kernels must reproduce it to round-off.
"""
from __future__ import annotations

import sys

import numpy as np

STEPS = 128
SEED = 5


def record(scene: str) -> dict:
    """Observations, rewards and the numeric info values of one seeded single env driven by
    pre-sampled uniform actions (``STEPS`` steps, no reset on the way)."""
    import rolling_env
    env = rolling_env.make(scene)
    obs, _ = env.reset(seed=SEED)
    acts = np.random.default_rng(SEED).uniform(-1, 1, (STEPS, 3)).astype(np.float32)
    rows = {"obs": [obs], "reward": []}
    for a in acts:
        obs, r, term, trunc, info = env.step(a)
        rows["obs"].append(obs)
        rows["reward"].append(r)
        for k, v in info.items():
            if isinstance(v, float):
                rows.setdefault("info_" + k, []).append(v)
        assert not (term or trunc), f"{scene}: episode ended within {STEPS} steps"
    return {k: np.asarray(v) for k, v in rows.items()}


def main(out: str) -> None:
    import rolling_env
    data = {}
    for scene in rolling_env.list_scenes():
        for k, v in record(scene).items():
            data[f"{scene}/{k}"] = v
    np.savez_compressed(out, **data)
    print(f"wrote {out}: {len(data)} arrays")


if __name__ == "__main__":
    main(sys.argv[1])
