"""Record env trajectories as a regression reference for tests/physics/test_kernel_paths.py.

    python tests/make_golden.py tests/data/golden_env.npz

The committed file holds the transitions of the env as it is now (the exact runner step on
the stuck contact, the trailing edge's dissipation in the wear, sub-steps chosen from each
scene's accuracy).  It guards against unintended change, not against error: the physics
tests check every reported quantity from its definition.  Record it again, with a fresh
``NUMBA_CACHE_DIR``, only for a change of the transitions that is meant, and say why in the
commit.
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
