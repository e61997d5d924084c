"""Every controller of the comparison on held-out variants of its scene.

    python -m agents.generalise --runs results/agents --episodes 10 --out results

A variant changes one physics key of a shipped scene, one the controllers were not designed
or trained for (``variants``): the friction coefficient x0.5 and x2 (where it is finite), the
runner's mass x0.5 and x2, and the load x0.5 and x1.5 (where there is one).  The Eq. 32
baselines are designed on the nominal scene, and the agents (final models, checked to be
trained on the nominal scene as ``agents.evaluate`` checks them; a residual agent's baseline
built on the nominal scene too) act on the variant's env: each side knows what it knew.  The
feedback baseline re-plans from what it measures, so it adapts within an episode; the
agents adapt only as far as their observations let them.

Per scene and variant: the IQM final |error| / tolerance and slip work over runs x targets
with 95% stratified bootstrap intervals and the probability of improvement over the better
baseline (``agents.stats``); the held-out targets and seeds are the first ``--episodes`` of
``agents.evaluate``'s 20.
Writes ``generalisation.md`` and ``generalisation.csv`` under ``--out`` (all or nothing).
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import rolling_env
from rolling_env.cli.main import positive_int
from rolling_env.env.rollout import rollout
from rolling_env.env.scenes import variants
from rolling_env.io import staged

from .common import EVAL_SEED, atomic_write, scene_key
from .evaluate import EPISODES_MAX, controllers_for, episode_metrics, held_out_targets
from .loading import load_agent
from .report import _budget, _config_key
from .verdicts import BASELINES

SHIPPED = ("default", "heavy_inf_friction", "light_stiff", "loaded", "resonant")
COMPARED = 20  # targets per scene in results/comparison.md


def _nominal_controllers(scene: str, runs: Path, model: str = "final") -> dict:
    """The baselines and agents of ``agents.evaluate`` for the nominal scene (every run
    checked there); agents reloaded so that a residual agent's baseline is the nominal one."""
    env = rolling_env.make(scene)
    ctrls = controllers_for(scene, runs, env, model)
    for name, c in list(ctrls.items()):
        if name not in BASELINES:  # a fresh copy, its baseline designed on the nominal scene
            fresh = load_agent(c.run / c.file, env, base_scene=env.unwrapped.scene)
            fresh.file, fresh.run, fresh.numerics = c.file, c.run, c.numerics
            ctrls[name] = fresh
    env.close()
    return ctrls


def evaluate_variants(scene: str, runs: Path, episodes: int, ctrls: dict) -> list[dict]:
    """Rows (as ``agents.evaluate.evaluate_scene``'s, with per-episode lists) of every
    controller on every variant of ``scene``; a row's ``scene`` is ``<key> <variant>``."""
    # the first ``episodes`` of the comparison's targets (drawn as a set of COMPARED)
    targets = held_out_targets(scene, max(episodes, COMPARED))[:episodes]
    rows = []
    for label, overrides in variants(scene):
        env = rolling_env.make(scene, **overrides)
        tol = env.unwrapped.scene.tolerance
        for name, ctrl in ctrls.items():
            per = [
                episode_metrics(rollout(env, ctrl, seed=EVAL_SEED + i, target=t), tol)
                for i, t in enumerate(targets)
            ]
            row = {
                "scene": f"{scene_key(scene)} {label}",
                "variant": label,
                "base_scene": scene_key(scene),
                "controller": name,
                "tolerance": tol,
                "model_file": getattr(ctrl, "file", "-"),
                "episodes": len(per),
                "config_key": _config_key(getattr(ctrl, "run", None)),
                "train_env_steps": _budget(getattr(ctrl, "run", None))["train_env_steps"],
                "trained_numerics": getattr(ctrl, "numerics", ""),
            }
            for key in ("final_abs_error", "slip_work"):
                vals = [float(p[key]) for p in per]
                row[f"episode_{key}"] = vals
                row[f"{key}_mean"] = sum(vals) / len(vals)
            rows.append(row)
            print(
                f"{row['scene']:32s} {name:20s} final|e|/tol "
                f"{row['final_abs_error_mean'] / tol:8.2f}  slip "
                f"{row['slip_work_mean']:.3e} J",
                flush=True,
            )
        env.close()
    return rows


def write(rows: list[dict], stats: list[dict], out: Path, episodes: int) -> None:
    from .evaluate import numerics_marks
    from .stats import markdown

    marks = numerics_marks(rows)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["scene", "variant", "controller", "episode", "final_abs_error_tol", "slip_work"])
    for r in rows:
        for i, (e, s) in enumerate(zip(r["episode_final_abs_error"], r["episode_slip_work"])):
            w.writerow(
                [
                    r["base_scene"],
                    r["variant"],
                    r["controller"],
                    i,
                    repr(e / r["tolerance"]),
                    repr(s),
                ]
            )
    atomic_write(out / "generalisation.csv", lambda p: Path(p).write_text(buf.getvalue()))
    lines = [
        "# Controllers on held-out variants of their scenes",
        "",
        "Generated by `python -m agents.generalise` (see docs/agents.md).  Each variant "
        "changes one physics key of a shipped scene (friction coefficient x0.5 and x2 "
        "where finite, runner mass x0.5 and x2, load x0.5 and x1.5 where there is one); "
        "the baselines are designed and the agents trained on the nominal scene, and "
        f"each controller runs the first {episodes} of comparison.md's {COMPARED} "
        f"held-out targets (env seed {EVAL_SEED} + i).  Per-episode values in "
        "generalisation.csv.",
        "",
    ]
    lines += markdown(stats, marks)[1:]  # the section's own heading is this file's
    if marks:
        lines += [""] + [
            f"* [{k}] trained on other numerics or reward weights: {note}"
            for note, k in marks.items()
        ]
    atomic_write(out / "generalisation.md", lambda p: Path(p).write_text("\n".join(lines) + "\n"))


def main(argv=None):
    p = argparse.ArgumentParser(
        prog="python -m agents.generalise", description=__doc__.splitlines()[0]
    )
    p.add_argument(
        "--scenes",
        nargs="+",
        default=list(SHIPPED),
        help="scene names or YAML files (default: the shipped scenes)",
    )
    p.add_argument("--runs", default="runs", help="folder of run folders <runs>/<scene>/*/")
    p.add_argument("--episodes", type=positive_int("episodes", 1, EPISODES_MAX), default=10)
    p.add_argument("--out", default="results")
    args = p.parse_args(argv)
    runs, out = Path(args.runs), Path(args.out)
    if not runs.is_dir():
        p.error(f"--runs: no folder {str(runs)!r}")
    from .baselines import Eq32Design
    from .common import buildable_scene

    for scene in args.scenes:
        try:
            Eq32Design(buildable_scene(scene))
        except ValueError as e:
            p.error(f"--scenes: {e}")
    try:
        setups = [(s, _nominal_controllers(s, runs)) for s in args.scenes]
    except (ValueError, OSError, KeyError) as e:
        p.error(f"--runs: {e}")
    from .stats import seed_statistics

    rows = []
    for scene, ctrls in setups:
        rows += evaluate_variants(scene, runs, args.episodes, ctrls)
    stats = seed_statistics(rows)
    out.mkdir(parents=True, exist_ok=True)
    with staged():
        write(rows, stats, out, args.episodes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
