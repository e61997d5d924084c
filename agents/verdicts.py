"""Verdicts on the comparison's rows, shared by the tables (``evaluate``) and the statistics
(``stats``): the goal against the better Eq. 32 baseline, the time a run took to meet it, the
grouping of runs by seed and the footnote marks of runs trained on other numerics."""

from __future__ import annotations

import re

import numpy as np

BASELINES = ("eq32-open-loop", "eq32-feedback")


def goal_verdicts(rows: list[dict]) -> list[dict]:
    """Per scene: the best baseline (lowest mean final |error|) against each trained agent.
    The goal: final error <= half the baseline's at no more slip work."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene]
        base = [r for r in rs if r["controller"] in BASELINES]
        if not base:
            continue
        b = min(base, key=lambda r: r["final_abs_error_mean"])
        for r in rs:
            if r["controller"] in BASELINES:
                continue
            e_ratio = r["final_abs_error_mean"] / b["final_abs_error_mean"]
            w_b, w_a = b["slip_work_mean"], r["slip_work_mean"]
            no_more_wear = w_a <= w_b  # both exactly 0 with mu = inf
            out.append(
                {
                    "scene": scene,
                    "agent": r["controller"],
                    "baseline": b["controller"],
                    "error_ratio": e_ratio,
                    "slip_ratio": (w_a / w_b) if w_b > 0 else (np.nan if w_a == 0 else np.inf),
                    "met": bool(e_ratio <= 0.5 and no_more_wear),
                    "time_to_goal": time_to_goal(r.get("goal_log"), b),
                }
            )
    return out


def time_to_goal(log, base: dict):
    """(env steps, wall seconds) of the first periodic evaluation in which the agent met the
    goal against the baseline row ``base``: the mean final |error| of its episodes at most
    half the baseline's mean over the held-out targets, at no more mean slip work.  None
    where the run has no log, "never" where no evaluation met it."""
    if log is None:
        return None
    for e in log:
        err, slip = np.mean(e["final_abs_error"]), np.mean(e["slip_work"])
        if err <= 0.5 * base["final_abs_error_mean"] and slip <= base["slip_work_mean"]:
            return int(e["env_steps"]), float(e["wall_seconds"])
    return "never"


_SEED_SUFFIX = re.compile(r"^(?P<name>.+)_seed(?P<seed>\d+)$")


def seed_groups(rows: list[dict]) -> dict:
    """``{(scene, name): [(row, seed), ...]}`` of the agents named ``<name>_seed<N>``
    (agents.train's run folders); baselines and other names are left out."""
    groups: dict = {}
    for r in rows:
        m = _SEED_SUFFIX.match(r["controller"])
        if r["controller"] in BASELINES or m is None:
            continue
        groups.setdefault((r["scene"], m["name"]), []).append((r, int(m["seed"])))
    return groups


def one_configuration(rs: list[dict]) -> bool:
    """Whether runs differ only in their seed: the same configuration (config.yml less the
    seed), model file and training steps."""
    kinds = {(r.get("config_key"), r.get("model_file"), r.get("train_env_steps")) for r in rs}
    return len(kinds) == 1


def numerics_marks(rows: list[dict]) -> dict:
    """``{note: k}``: footnote number k (from 1, in the order of the rows) of each distinct
    ``trained_numerics`` note of the rows (agents trained on other numerics of their scene)."""
    marks: dict = {}
    for r in rows:
        note = r.get("trained_numerics") or ""
        if note and note not in marks:
            marks[note] = len(marks) + 1
    return marks


def marked(name: str, notes, marks: dict) -> str:
    """``name [k]`` with the footnote numbers of ``notes`` (one note or several)."""
    notes = [notes] if isinstance(notes, str) else list(notes)
    ks = sorted({marks[n] for n in notes if n})
    return name + "".join(f" [{k}]" for k in ks)
