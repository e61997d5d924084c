"""Statistics over seeds for the comparison, computed with rliable (Agarwal et al., 2021).

For each scene and configuration (the runs ``<name>_seed<N>`` that differ only in their seed;
a baseline is a configuration with one run) the scores form a matrix of runs x held-out
targets (rliable's runs x tasks).  Reported per configuration:

* the interquartile mean (IQM) of the final |error| / tolerance and of the slip work over
  all runs x episodes, with 95% stratified bootstrap intervals (runs resampled within each
  target; a configuration with one run, a baseline, has a zero-width interval: its spread
  over targets is in the tables of means);
* the probability of improvement over the better baseline (the one with the lower mean
  final error, as in the goal table): the chance that a run of the configuration ends closer to
  the target than
  the baseline on the same target, averaged over targets, with its interval;
* the seeds that meet the goal (``verdicts.goal_verdicts``), and whether the configuration
  holds the goal over seeds: at least 4 of 5 seeds meet it (80% of the runs where there are
  other counts) and the upper end of the IQM interval lies below half the better baseline's
  IQM.
"""

from __future__ import annotations

import numpy as np

REPS = 2000  # bootstrap resamples of the IQM
REPS_POI = 500  # of the probability of improvement (a Mann-Whitney test per target and resample)
CONFIDENCE = 0.95
SEED = 20261127  # of the bootstrap: the tables regenerate exactly
MIN_SHARE = 0.8  # share of seeds that must meet the goal (4 of 5)


def _groups(rows: list[dict]) -> dict:
    """{(scene, configuration): [rows]}: each baseline alone, the runs ``<name>_seed<N>`` of
    one configuration together (``verdicts.seed_groups``, ``one_configuration``), any other
    run alone."""
    from .verdicts import one_configuration, seed_groups

    group_of = {}  # row id -> its configuration's key
    for (scene, name), members in seed_groups(rows).items():
        rs = [r for r, _ in members]
        if one_configuration(rs):
            group_of.update((id(r), (scene, name)) for r in rs)
    out: dict = {}  # in the order of the rows, as the tables list them
    for r in rows:  # baselines, runs without a seed, runs of mixed configurations alone
        out.setdefault(group_of.get(id(r), (r["scene"], r["controller"])), []).append(r)
    return out


def _matrix(rs: list[dict], key: str, scale: float = 1.0) -> np.ndarray:
    """runs x episodes matrix of a per-episode quantity."""
    n = {len(r[key]) for r in rs}
    if len(n) != 1:
        raise ValueError(f"runs {[r['controller'] for r in rs]} have different episode counts")
    return np.array([np.asarray(r[key], float) / scale for r in rs])


def _intervals(scores: dict, func, reps: int, seed: int):
    """rliable's point estimates and stratified bootstrap intervals of ``func`` over
    ``scores`` ({configuration: runs x targets}), ``reps`` resamples drawn with ``seed``."""
    import warnings

    from rliable import library as rly

    # rliable's stratified bootstraps draw from numpy's global generator: seeded here
    # for tables that regenerate exactly, and the caller's state put back after
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        with warnings.catch_warnings():  # rliable hands arch a RandomState, which
            warnings.filterwarnings(
                "ignore", message="random_state is deprecated", category=FutureWarning
            )  # arch will stop taking
            return rly.get_interval_estimates(
                scores, func, reps=reps, confidence_interval_size=CONFIDENCE
            )
    finally:
        np.random.set_state(saved)


def seed_statistics(
    rows: list[dict], reps: int = REPS, seed: int = SEED, reps_poi: int = REPS_POI
) -> list[dict]:
    """One dict per scene and configuration (see the module): rows from
    ``evaluate.evaluate_scene`` (with their per-episode lists)."""
    from .verdicts import goal_verdicts

    verdicts = {(v["scene"], v["agent"]): v["met"] for v in goal_verdicts(rows)}
    groups = _groups(rows)
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        configs = {k[1]: rs for k, rs in groups.items() if k[0] == scene}
        out += _scene_statistics(scene, configs, verdicts, reps, seed, reps_poi)
    return out


def _scene_statistics(scene, configs: dict, verdicts: dict, reps, seed, reps_poi) -> list:
    """``seed_statistics``' dicts of one scene (``configs``: {configuration: its rows};
    ``verdicts``: {(scene, agent): goal met})."""
    from rliable import metrics

    from .verdicts import BASELINES

    err, slip = {}, {}
    for name, rs in configs.items():
        tol = rs[0]["tolerance"]
        err[name] = _matrix(rs, "episode_final_abs_error", tol)
        slip[name] = _matrix(rs, "episode_slip_work", 1e-9)  # nJ
    pt_e, ci_e = _intervals(err, metrics.aggregate_iqm, reps, seed)
    pt_s, ci_s = _intervals(slip, metrics.aggregate_iqm, reps, seed)
    iqm = {name: float(np.asarray(pt_e[name]).reshape(-1)[0]) for name in err}
    bases = [b for b in BASELINES if b in err]
    # the better baseline as the goal tables choose it: the lower mean final error
    best = min(bases, key=lambda b: float(err[b].mean())) if bases else None
    pairs = {
        name: (-err[name], -err[best]) for name in err if best is not None and name not in BASELINES
    }
    if pairs:
        pt_p, ci_p = _intervals(pairs, metrics.probability_of_improvement, reps_poi, seed)
    out = []
    for name, rs in configs.items():
        lo, hi = np.asarray(ci_e[name]).reshape(2)
        s_lo, s_hi = np.asarray(ci_s[name]).reshape(2)
        row = {
            "scene": scene,
            "config": name,
            "runs": len(rs),
            "episodes": err[name].shape[1],
            "baseline": best,
            "iqm_error": iqm[name],
            "iqm_error_lo": float(lo),
            "iqm_error_hi": float(hi),
            "iqm_slip": float(np.asarray(pt_s[name]).reshape(-1)[0]),
            "iqm_slip_lo": float(s_lo),
            "iqm_slip_hi": float(s_hi),
            "controllers": [r["controller"] for r in rs],
            "trained_numerics": sorted({r.get("trained_numerics") or "" for r in rs}),
        }
        if name in pairs:
            p_lo, p_hi = np.asarray(ci_p[name]).reshape(2)
            met = [verdicts[(scene, c)] for c in row["controllers"] if (scene, c) in verdicts]
            ratio_hi = row["iqm_error_hi"] / iqm[best] if iqm[best] > 0 else np.inf
            row.update(
                poi=float(np.asarray(pt_p[name]).reshape(-1)[0]),
                poi_lo=float(p_lo),
                poi_hi=float(p_hi),
                met=sum(met),
                judged=len(met),
                iqm_ratio_hi=float(ratio_hi),
                holds=bool(met and sum(met) >= MIN_SHARE * len(met) and ratio_hi < 0.5),
            )
        out.append(row)
    return out


def markdown(stats: list[dict], marks: dict | None = None) -> list[str]:
    """The statistics section of comparison.md."""
    from .verdicts import marked

    marks = marks or {}
    lines = [
        "## Over seeds and targets (rliable)",
        "",
        f"Interquartile mean (IQM) over runs x held-out targets with {CONFIDENCE:.0%} "
        f"stratified bootstrap intervals ({REPS} resamples, {REPS_POI} for "
        f"P(improvement); seed {SEED}); a baseline is one run, so its interval has "
        "zero width.  *P(improvement)*: the probability that a run of the "
        "configuration ends closer to the target than the better baseline (lower mean "
        "final error) on the same target, averaged over the targets.  *Holds*: "
        f"at least {MIN_SHARE:.0%} of the seeds meet the goal above and the upper end "
        "of the IQM interval lies below half the better baseline's IQM.",
        "",
        "| scene | configuration | runs | IQM final error / tol [95% CI] | IQM slip work "
        "[nJ] [95% CI] | P(improvement) over | seeds meeting the goal | holds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in stats:
        name = marked(s["config"], s["trained_numerics"], marks)
        poi = (
            f"{s['poi']:.2f} [{s['poi_lo']:.2f}, {s['poi_hi']:.2f}] {s['baseline']}"
            if "poi" in s
            else "-"
        )
        goal = f"{s['met']} of {s['judged']}" if "met" in s else "-"
        holds = ("yes" if s["holds"] else "no") if "holds" in s else "-"
        lines.append(
            f"| {s['scene']} | {name} | {s['runs']} | {s['iqm_error']:.3g} "
            f"[{s['iqm_error_lo']:.3g}, {s['iqm_error_hi']:.3g}] | "
            f"{s['iqm_slip']:.3g} [{s['iqm_slip_lo']:.3g}, {s['iqm_slip_hi']:.3g}] | "
            f"{poi} | {goal} | {holds} |"
        )
    return lines


def plot_intervals(stats: list[dict], path) -> None:
    """One panel per scene: the IQM final error / tolerance of each configuration with its
    interval (log axis), the better baseline's IQM and half of it as lines."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .common import atomic_write

    scenes = list(dict.fromkeys(s["scene"] for s in stats))
    fig = Figure(figsize=(7, 1.2 + 0.45 * len(stats)))  # no pyplot: no global state touched
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(scenes), 1, squeeze=False)
    for ax, scene in zip(axes[:, 0], scenes):
        ss = [s for s in stats if s["scene"] == scene]
        y = np.arange(len(ss))[::-1]
        for yi, s in zip(y, ss):
            lo, hi = max(s["iqm_error_lo"], 1e-3), max(s["iqm_error_hi"], 1e-3)
            ax.plot([lo, hi], [yi, yi], lw=6, alpha=0.5, color="C0" if "poi" in s else "0.5")
            ax.plot([max(s["iqm_error"], 1e-3)], [yi], "k|", ms=12)
        ref = next((s for s in ss if s["config"] == ss[0].get("baseline")), None)
        if ref is not None:
            ax.axvline(ref["iqm_error"], color="C3", lw=1, label="better baseline")
            ax.axvline(0.5 * ref["iqm_error"], color="C3", lw=1, ls="--", label="half of it")
        ax.set_yticks(y, [s["config"] for s in ss], fontsize=8)
        ax.set_xscale("log")
        ax.set_title(scene, fontsize=9, loc="left")
        ax.grid(axis="x", alpha=0.3)
    axes[-1, 0].set_xlabel("IQM final |error| / tolerance (95% stratified bootstrap CI)")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    atomic_write(path, lambda p: fig.savefig(p, dpi=100, format="png"))
