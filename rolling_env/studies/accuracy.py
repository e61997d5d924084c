"""Error of the env at a scene's shipped numerics against a refined reference, with its speed.

Per scene, the standard episodes are run at the shipped settings (``rolling_env.make(scene)``)
and their actions recorded: one episode of the Eq. 32 feedback baseline, one of the Eq. 32
open-loop baseline, and ``episodes_random`` episodes of uniform random actions (pre-sampled
from ``numpy.random.default_rng(seed)``), ``episodes_bang_bang`` episodes of bang-bang actions
(each tick a random corner of the action box, from their own generator: every other tick on
average the load drops to N_min, lift-off where N_min = 0, and the rolling rate and the creep
reverse at full size), ``episodes_constant`` episodes of one action held throughout (uniform
in the action box, from a third generator: rolling with creep to the stroke's end, then a
stopped contact on which the runner rings against the edges' microslip), and optionally one
deterministic episode of each
trained agent given (the first seed of each configuration under a runs folder, kind
``agent``).  Each action sequence is then replayed open loop,
so that no feedback can hide a drift, at the shipped settings (timed: steps per second) and at
two refined levels: sub-steps x K with the grid (cells per contact radius) x G, and sub-steps
x 2K with the grid x 2G.  The two levels differ by a factor 2 in both, and their final runner
position x* and slip work are Richardson-extrapolated assuming second order in that factor:
ref = fine + (fine - coarse) / (2^2 - 1).  The difference of the two levels is reported as
the reference's own uncertainty: it bounds the extrapolated reference's error where the error
is at least first order and in its asymptotic range (first order leaves 2/3 of it, second
order much less).

The grid is refined too, by G = 4 by default, not 2: on random actions, which reverse the
rolling and change the load every tick, the grid error of x* is first order, and grids x2 /
x4 left 0.5 tolerance between the levels on heavy_inf_friction, x4 / x8 0.03.  With the
default K = 8 the shipped scenes' reference uncertainties stay below 0.01 tolerance on x*
(results/env_accuracy.md); the uncertainty column says where a larger K is needed.

The shipped sub-steps and resolution are read from the built env, never from the scene file
(a scene may resolve them when it is built); every level passes both explicitly.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from rolling_env.validation import check_int

ORDER = 2.0  # assumed order of the error in the refinement factor (Richardson)
DEFAULT_REFINE = 8  # K: sub-steps x K and x 2K at the two reference levels
DEFAULT_GRID = 4  # G: the grid (resolution) x G and x 2G at the two reference levels
TIMING_REPEATS = 3  # the shipped replay is timed this often; the fastest run counts
KINDS = ("eq32-feedback", "eq32-open-loop", "random", "bang-bang", "constant", "agent")
#: the env's accuracy targets (final x* in tolerances, slip work in %): a reference whose two
#: levels differ by more cannot tell whether an episode meets them
TARGET_XSTAR_TOL = 0.1
TARGET_SLIP_PCT = 2.0
UNCERTAIN_NOTE = (
    f"reference uncertain by more than the targets ({TARGET_XSTAR_TOL:g} tolerance, "
    f"{TARGET_SLIP_PCT:g}% slip work): its two levels disagree, so the error is only a rough "
    "size; refine the reference (a larger --refine-grid, or --refine)"
)


def shipped_numerics(env) -> tuple[int, float]:
    """(sub_steps per tick, cells per contact radius) of a built env, as it resolved them."""
    sc = env.unwrapped.scene
    return int(sc.n_sub), float(sc.resolution)


def levels(
    refine: int = DEFAULT_REFINE, grid: int = DEFAULT_GRID
) -> tuple[tuple[int, int], tuple[int, int]]:
    """The reference levels as (sub-step factor, grid factor) pairs over the shipped
    settings: (K, G) and (2K, 2G)."""
    for name, k in (("refine", refine), ("grid", grid)):
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {k!r}")
    return (int(refine), int(grid)), (2 * int(refine), 2 * int(grid))


def _make(scene, sub_steps=None, resolution=None, overrides=None):
    import rolling_env

    kw = dict(overrides or {})
    if sub_steps is not None:
        kw.update(sub_steps=int(sub_steps), resolution=float(resolution))
    return rolling_env.make(scene, **kw)


def check_levels(scene, level_factors, overrides=None) -> list[tuple[int, float]]:
    """The absolute (sub_steps, resolution) of each reference level of ``scene``; each level's
    env is built once, so that a level the scene cannot take (too many sub-steps, a grid too
    fine for the stroke) is refused before any episode runs."""
    env = _make(scene, overrides=overrides)
    s0, r0 = shipped_numerics(env)
    env.close()
    out = []
    for fs, fg in level_factors:
        s, r = s0 * int(fs), r0 * float(fg)
        try:
            _make(scene, s, r, overrides).close()
        except ValueError as e:
            raise ValueError(
                f"the reference level with sub_steps {s} and resolution {r:g} "
                f"(x{fs} and x{fg:g} the shipped {s0} and {r0:g}) cannot be "
                f"built: {e}"
            ) from None
        out.append((s, r))
    return out


def check_scene(scene, overrides=None) -> None:
    """Build the scene's env and both Eq. 32 baselines, so that a scene that does not load, or
    that the baselines cannot drive, is refused before any episode runs."""
    from rolling_env.env.baselines import Eq32Feedback, Eq32OpenLoop

    env = _make(scene, overrides=overrides)
    try:
        Eq32Feedback.from_env(env)
        Eq32OpenLoop.from_env(env)
    finally:
        env.close()


class _Sequence:
    """A controller that plays a recorded action sequence (SB3's ``predict``)."""

    def __init__(self, actions: np.ndarray):
        self.actions = actions
        self.k = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        a = self.actions[self.k]
        self.k += 1
        return a, state


def _stream(seed, steps, episodes, kind: int):
    """The checked counts and the generator ``default_rng([seed, kind])`` of one kind of
    pre-sampled episode: a stream of its own, so that adding episodes of one kind leaves the
    others of ``seed`` (the uniform random ones from ``default_rng(seed)``) as they were."""
    seed = check_int("seed", seed, 0, 2**63 - 1)
    steps = check_int("steps", steps, 1, 10**8)
    episodes = check_int("episodes", episodes, 0, 10**6)
    return np.random.default_rng([seed, kind]), steps, episodes


def bang_bang_actions(seed: int, steps: int, episodes: int) -> list[np.ndarray]:
    """``episodes`` sequences of ``steps`` bang-bang actions (each component -1 or +1, drawn
    with equal odds) from ``numpy.random.default_rng([seed, 1])`` (``_stream``)."""
    rng, steps, episodes = _stream(seed, steps, episodes, 1)
    corners = np.array([-1.0, 1.0], dtype=np.float32)
    return [rng.choice(corners, (steps, 3)) for _ in range(episodes)]


def constant_actions(seed: int, steps: int, episodes: int) -> list[np.ndarray]:
    """``episodes`` sequences of ``steps`` copies of one action, each drawn uniformly from the
    action box by ``numpy.random.default_rng([seed, 2])`` (``_stream``)."""
    rng, steps, episodes = _stream(seed, steps, episodes, 2)
    held = rng.uniform(-1.0, 1.0, (episodes, 3)).astype(np.float32)
    return [np.tile(a, (steps, 1)) for a in held]


def record(
    scene,
    kind: str,
    seed: int = 0,
    actions: np.ndarray | None = None,
    overrides=None,
    model: str | None = None,
) -> dict:
    """One episode of ``kind`` at the shipped settings: its actions (float32, as the
    controllers give them), final x* [m], total slip work [J] and target [m].  ``random``,
    ``bang-bang`` and ``constant`` play ``actions`` (pre-sampled); ``agent`` the trained
    ``model`` (an SB3 .zip, loaded by ``rollout.make_controller``, deterministic)."""
    from rolling_env.env.baselines import Eq32Feedback, Eq32OpenLoop
    from rolling_env.env.rollout import make_controller, rollout

    env = _make(scene, overrides=overrides)
    if kind == "eq32-feedback":
        ctrl = Eq32Feedback.from_env(env)
    elif kind == "eq32-open-loop":
        ctrl = Eq32OpenLoop.from_env(env)
    elif kind in ("random", "bang-bang", "constant"):
        ctrl = _Sequence(actions)
    elif kind == "agent":
        ctrl = make_controller(str(model), env, seed=seed, scene=scene)
    else:
        raise ValueError(f"episode kind must be one of {', '.join(KINDS)}, got {kind!r}")
    data = rollout(env, ctrl, seed=seed)
    env.close()
    acts = np.stack([data["a_force"], data["a_roll"], data["a_creep"]], axis=1)
    return {
        "actions": acts.astype(np.float32),
        "xstar": float(data["xstar"][-1]),
        "slip_work": data["total_slip_work"],
        "target": float(data["target"][-1]),
    }


def replay(
    scene,
    actions: np.ndarray,
    seed: int = 0,
    sub_steps=None,
    resolution=None,
    overrides=None,
    repeats: int = 1,
) -> dict:
    """Replay ``actions`` open loop (a fresh env per run, reset with ``seed``) at
    ``sub_steps`` and ``resolution`` (None: the shipped ones).  Returns the final x* [m], the
    total slip work [J] and the fastest of ``repeats`` step loops in seconds and steps/s."""
    best = math.inf
    xstar = slip = None
    for _ in range(max(1, repeats)):
        env = _make(scene, sub_steps, resolution, overrides)
        env.reset(seed=seed)
        work = []
        info = {"xstar": 0.0}
        t = time.perf_counter()
        for a in actions:
            _, _, _, _, info = env.step(a)
            work.append(info["slip_work"])
        best = min(best, time.perf_counter() - t)
        env.close()
        s = float(np.sum(work))  # summed as rollout sums it: a faithful replay is bit-equal
        if xstar is not None and (info["xstar"] != xstar or s != slip):
            raise RuntimeError(
                "the env is not deterministic: two replays of one action sequence differ"
            )
        xstar, slip = info["xstar"], s
    return {
        "xstar": float(xstar),
        "slip_work": float(slip),
        "seconds": best,
        "steps_per_s": len(actions) / best if best > 0 else math.inf,
    }


def richardson(coarse: float, fine: float, ratio: float, order: float = ORDER) -> float:
    """Extrapolate two values at refinement factors 1 and ``ratio`` (> 1) assuming an error
    ~ h^order; with ``ratio`` 1 the two levels are the same and ``fine`` is returned."""
    if ratio == 1.0 or coarse == fine:
        return fine
    return fine + (fine - coarse) / (ratio**order - 1.0)


def _level_ratio(level_factors) -> float:
    """The common refinement factor between the two levels (sub-steps and grid alike)."""
    (s1, g1), (s2, g2) = level_factors
    rs, rg = s2 / s1, g2 / g1
    if not (rs >= 1.0 and math.isclose(rs, rg)):
        raise ValueError(
            f"the two reference levels must refine the sub-steps and the grid by "
            f"one common factor >= 1, got x{rs:g} and x{rg:g}"
        )
    return rs


# slip work below this fraction of min(mu, 1) N_max x tolerance is round-off (a massless
# runner on an unloaded contact slides nowhere): its relative error is no measure of anything
SLIP_ROUNDOFF = 1e-12


def _rel_pct(value: float, ref: float, floor: float = 0.0) -> float | None:
    if ref == 0.0 or max(abs(value), abs(ref)) <= floor:
        return None
    return (value - ref) / abs(ref) * 100.0


def _uncertain_parts(e: dict) -> tuple[bool, bool]:
    """Whether an episode's reference is uncertain beyond the target in x* and in the slip
    work."""
    s = e["slip_uncertainty_pct"]
    return e["xstar_uncertainty_tol"] > TARGET_XSTAR_TOL, s is not None and s > TARGET_SLIP_PCT


def episode_result(
    kind: str,
    label: str,
    rec: dict,
    shipped: dict,
    refs: list[dict],
    ratio: float,
    order: float,
    tolerance: float,
    slip_floor: float = 0.0,
) -> dict:
    """The accuracy of one episode: errors of the shipped replay against the extrapolated
    reference, the reference's uncertainty (difference of its two levels) and the speeds.
    Slip work at or below ``slip_floor`` [J] (round-off) has no relative error (None)."""
    (c, f) = refs
    x_ref = richardson(c["xstar"], f["xstar"], ratio, order)
    s_ref = richardson(c["slip_work"], f["slip_work"], ratio, order)
    slip_err = _rel_pct(shipped["slip_work"], s_ref, slip_floor)
    slip_unc = None  # the levels' difference relative to the reference
    if slip_err is not None:
        slip_unc = abs(f["slip_work"] - c["slip_work"]) / abs(s_ref) * 100.0
    out = {
        "kind": kind,
        "label": label,
        "steps": len(rec["actions"]),
        "target": rec["target"],
        "replay_exact": (shipped["xstar"], shipped["slip_work"])
        == (rec["xstar"], rec["slip_work"]),
        "xstar_shipped": shipped["xstar"],
        "xstar_reference": x_ref,
        "xstar_error_tol": abs(shipped["xstar"] - x_ref) / tolerance,
        "xstar_uncertainty_tol": abs(f["xstar"] - c["xstar"]) / tolerance,
        "slip_work_shipped": shipped["slip_work"],
        "slip_work_reference": s_ref,
        "slip_error_pct": slip_err,
        "slip_uncertainty_pct": slip_unc,
        "steps_per_s": shipped["steps_per_s"],
        "levels": [
            {"xstar": r["xstar"], "slip_work": r["slip_work"], "steps_per_s": r["steps_per_s"]}
            for r in refs
        ],
    }
    out["reference_uncertain"] = any(_uncertain_parts(out))
    return out


def scene_accuracy(
    scene,
    refine: int = DEFAULT_REFINE,
    grid: int = DEFAULT_GRID,
    episodes_random: int = 1,
    seed: int = 0,
    overrides: dict | None = None,
    episodes_bang_bang: int = 1,
    episodes_constant: int = 1,
    level_factors=None,
    order: float = ORDER,
    timing_repeats: int = TIMING_REPEATS,
    models=(),
    variant: str | None = None,
    changes: str | None = None,
) -> dict:
    """The accuracy table of one scene (name, YAML path or dict; see the module docstring).

    ``models``: (label, path) pairs of trained agents (SB3 .zip) whose deterministic
    episodes are recorded and replayed like the others (kind ``agent``).  ``variant``: the
    label of the physics ``overrides`` change (a held-out variant, ``scenes.variants``);
    ``changes``: the label of scene keys a user changed (``--set``); both are reported
    beside the scene's name.

    ``overrides`` apply to every env built (the shipped one and the references), e.g.
    ``{"episode_steps": 64}`` for a quick check.  ``level_factors``: the two reference levels
    as (sub-step factor, grid factor) pairs over the shipped settings (default
    ``levels(refine, grid)``); both (1, 1) makes the reference the shipped settings
    themselves, so every error is exactly 0 where the replay is faithful."""
    t_start = time.perf_counter()
    factors = tuple(level_factors) if level_factors is not None else levels(refine, grid)
    ratio = _level_ratio(factors)
    abs_levels = check_levels(scene, factors, overrides)
    env = _make(scene, overrides=overrides)
    sc = env.unwrapped.scene
    s0, r0 = shipped_numerics(env)
    steps = sc.episode_steps
    slip_floor = SLIP_ROUNDOFF * min(sc.mu, 1.0) * sc.N_max * sc.tolerance
    env.close()

    rng = np.random.default_rng(seed)
    plan = [("eq32-feedback", "eq32-feedback", {}), ("eq32-open-loop", "eq32-open-loop", {})]
    for i in range(episodes_random):
        label = "random" if episodes_random == 1 else f"random {i + 1}"
        acts = rng.uniform(-1.0, 1.0, (steps, 3)).astype(np.float32)
        plan.append(("random", label, {"actions": acts}))
    bang = bang_bang_actions(seed, steps, episodes_bang_bang)
    for i, acts in enumerate(bang):
        label = "bang-bang" if len(bang) == 1 else f"bang-bang {i + 1}"
        plan.append(("bang-bang", label, {"actions": acts}))
    for acts in constant_actions(seed, steps, episodes_constant):
        label = "constant (" + ", ".join(f"{x:+.2f}" for x in acts[0]) + ")"
        plan.append(("constant", label, {"actions": acts}))
    plan += [("agent", label, {"model": path}) for label, path in models]

    episodes = []
    for kind, label, what in plan:
        rec = record(scene, kind, seed, overrides=overrides, **what)
        shipped = replay(scene, rec["actions"], seed, overrides=overrides, repeats=timing_repeats)
        refs = [replay(scene, rec["actions"], seed, s, r, overrides) for s, r in abs_levels]
        episodes.append(
            episode_result(kind, label, rec, shipped, refs, ratio, order, sc.tolerance, slip_floor)
        )
    return {
        "scene": sc.name,
        "variant": variant,
        "changes": changes,
        "tolerance": sc.tolerance,
        "episode_steps": steps,
        "seed": seed,
        "shipped": {"sub_steps": s0, "resolution": r0},
        "levels": [{"sub_steps": s, "resolution": r} for s, r in abs_levels],
        "order": order,
        "ratio": ratio,
        "episodes": episodes,
        "seconds": time.perf_counter() - t_start,
    }


def run(scenes, models=None, variants: bool = False, overrides=None, changes=None, **kw) -> dict:
    """``scene_accuracy`` of each scene: ``{"scenes": [...], "seconds": total}``;
    ``models`` maps a scene (as given) to its (label, path) pairs of agents; ``variants``
    runs each scene's held-out variants (``scenes.variants``) instead of the scene;
    ``changes`` names the scene keys the ``overrides`` change (``--set``)."""
    from rolling_env.env.scenes import variants as scene_variants

    t = time.perf_counter()
    res = []
    for s in scenes:
        ms = (models or {}).get(s, ())
        plan = scene_variants(s) if variants else [(None, {})]
        for label, ov in plan:
            o = {**(overrides or {}), **ov} or None
            res.append(
                scene_accuracy(s, models=ms, overrides=o, variant=label, changes=changes, **kw)
            )
    return {"scenes": res, "seconds": time.perf_counter() - t}


def _title(res: dict) -> str:
    return " ".join(x for x in (res["scene"], res.get("variant"), res.get("changes")) if x)


def agent_models(runs_dir, scene_name: str) -> list[tuple[str, str]]:
    """The first seed of every agent configuration committed for a scene: (run folder name,
    its ``model.zip``) for each ``runs_dir/<scene_name>/<config>_seed0/model.zip``, in name
    order; none where the scene has no runs."""
    from pathlib import Path

    folder = Path(runs_dir) / scene_name
    found = sorted(folder.glob("*_seed0/model.zip")) if folder.is_dir() else []
    return [(p.parent.name, str(p)) for p in found]


# ----------------------------------------------------------------------------- output
def _f(x, fmt: str, unit: str = "", width: int = 0) -> str:
    """``x`` formatted with its unit, or "-" for None (no reference slip work)."""
    return ("-" if x is None else format(x, fmt) + unit).rjust(width)


def _unc(e: dict) -> str:
    mx, ms = (" *" if u else "" for u in _uncertain_parts(e))
    return (
        f"{e['xstar_uncertainty_tol']:.3g} tol{mx}, {_f(e['slip_uncertainty_pct'], '.2g', '%')}{ms}"
    )


def table(res: dict) -> str:
    """The human table of one scene's result."""
    lv = ", ".join(f"({lev['sub_steps']}, {lev['resolution']:g})" for lev in res["levels"])
    head = (
        f"{_title(res)}: shipped sub_steps {res['shipped']['sub_steps']}, resolution "
        f"{res['shipped']['resolution']:g}; reference Richardson (order {res['order']:g}) "
        f"of (sub_steps, resolution) = {lv}; tolerance {res['tolerance']:g} m, "
        f"{res['episode_steps']} steps, seed {res['seed']}"
    )
    w = max([16] + [len(e["label"]) for e in res["episodes"]])
    lines = [
        head,
        f"  {'episode':{w}s} {'x* error':>12s} {'slip error':>11s} {'steps/s':>9s}"
        f"   reference uncertainty (x*, slip)",
        f"  {'':{w}s} {'[tol]':>12s} {'[%]':>11s}",
    ]
    for e in res["episodes"]:
        lines.append(
            f"  {e['label']:{w}s} {e['xstar_error_tol']:12.4g} "
            f"{_f(e['slip_error_pct'], '+.2f', width=11)} {e['steps_per_s']:9.0f}"
            f"   {_unc(e)}"
        )
    if any(e["reference_uncertain"] for e in res["episodes"]):
        lines.append(f"  * {UNCERTAIN_NOTE}")
    if not all(e["replay_exact"] for e in res["episodes"]):
        lines.append("  WARNING: a replay at the shipped settings differs from its recording")
    lines.append(f"  [{res['seconds']:.1f} s]")
    return "\n".join(lines)


def report(results: list[dict], command: str, seconds: float) -> str:
    """Markdown report of one or more scenes' results."""
    lines = [
        "# Accuracy of the env at the shipped settings, against a refined reference",
        "",
        f"Generated by `{command}` ({seconds:.0f} s on a machine with {os.cpu_count()} CPUs; "
        "see `docs/accuracy.md` for the method).  Per scene, each episode's actions are "
        "recorded at the scene's shipped settings and replayed open loop there and at two "
        "refined levels (sub-steps, cells per contact radius); the reference is their "
        f"Richardson extrapolation assuming order {results[0]['order']:g} in the common "
        "refinement factor, and *uncertainty* is the difference of the two levels (x* in "
        "tolerances, slip work in % of the reference).  *x\\* error*: |x\\*(shipped) - "
        "x\\*(reference)| / the scene's tolerance; *slip error*: (shipped - reference) / "
        "reference, negative = the shipped env underestimates the wear, `-` where the "
        "reference has no slip work (infinite friction) or only round-off.  *steps/s*: one "
        "env's step loop at "
        "the shipped settings (`rolling_env.make`, pre-recorded actions, fastest of "
        f"{TIMING_REPEATS}); the reference levels' speeds follow.",
        "",
    ]
    if any(r.get("variant") for r in results):
        lines += [
            "Each section is a held-out variant of a shipped scene: one physics key scaled "
            "(`rolling_env.env.scenes.variants`), every other key and the numerics rule as shipped "
            "(`sub_steps: auto` follows the changed physics; the grid is the scene's).",
            "",
        ]
    if any(r.get("changes") for r in results):
        lines += [
            f"Scene keys changed for every env of the run (`--set`): {results[0]['changes']}.",
            "",
        ]
    for res in results:
        lv = [f"({lev['sub_steps']}, {lev['resolution']:g})" for lev in res["levels"]]
        lines += [
            f"## {_title(res)}",
            "",
            f"Shipped: {res['shipped']['sub_steps']} sub-steps per tick, "
            f"{res['shipped']['resolution']:g} cells per contact radius; reference levels "
            f"{' and '.join(lv)}; tolerance {res['tolerance']:g} m; {res['episode_steps']} "
            f"steps per episode, seed {res['seed']}; {res['seconds']:.1f} s.",
            "",
            "| episode | x* error [tol] | x* uncertainty [tol] | slip error | slip "
            "uncertainty | x* shipped [m] | x* reference [m] | slip work reference [J] | "
            "steps/s shipped | steps/s " + " | steps/s ".join(lv) + " |",
            "|---|---|---|---|---|---|---|---|---|" + "---|" * len(lv),
        ]
        for e in res["episodes"]:
            speeds = " | ".join(f"{lev['steps_per_s']:.0f}" for lev in e["levels"])
            mx, ms = (" \\*" if u else "" for u in _uncertain_parts(e))
            lines.append(
                f"| {e['label']} | {e['xstar_error_tol']:.3g} | "
                f"{e['xstar_uncertainty_tol']:.2g}{mx} | "
                f"{_f(e['slip_error_pct'], '+.1f', '%')} | "
                f"{_f(e['slip_uncertainty_pct'], '.2g', '%')}{ms} | "
                f"{e['xstar_shipped']:.5e} | {e['xstar_reference']:.5e} | "
                f"{e['slip_work_reference']:.4e} | {e['steps_per_s']:.0f} | {speeds} |"
            )
        if any(e["reference_uncertain"] for e in res["episodes"]):
            lines += ["", f"\\* {UNCERTAIN_NOTE}."]
        if not all(e["replay_exact"] for e in res["episodes"]):
            lines += [
                "",
                "**Warning**: a replay at the shipped settings differs from its "
                "recording (the env is not deterministic).",
            ]
        lines.append("")
    return "\n".join(lines)
