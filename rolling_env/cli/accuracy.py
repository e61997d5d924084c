"""Subcommand accuracy: the env's error at a scene's shipped settings against a refined
reference, with its speed (``--all --out results/env_accuracy.md`` for every shipped scene)."""

from __future__ import annotations

from rolling_env.cli.main import emit, file_path, positive_int

REPORT = "results/env_accuracy.md"


def register(sub):
    from rolling_env.studies.accuracy import DEFAULT_GRID, DEFAULT_REFINE

    p = sub.add_parser(
        "accuracy",
        help="error of the env at a scene's shipped settings against "
        "a refined reference, and its steps/s",
        description="Run the scene's standard episodes at its shipped settings "
        "(Eq. 32 feedback, Eq. 32 open loop, uniform random actions, bang-bang actions "
        "(each tick a random corner of the action box), one action held throughout, and "
        "with --agents "
        "one of each trained agent configuration), replay each "
        "action sequence open loop at two refined levels (sub-steps x K and 2K, "
        "grid x G and 2G), extrapolate them (Richardson, assumed second order) "
        "and print the shipped env's final-position error in tolerances, its "
        "slip-work error in %, its steps/s and the reference's uncertainty.  "
        f"`--all --out {REPORT}` regenerates the report of every shipped scene.",
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--scene", help="scene name or YAML path")
    which.add_argument(
        "--all", action="store_true", help="every shipped scene (configs/scenes/*.yaml)"
    )
    p.add_argument(
        "--refine",
        type=positive_int("refine", 1, 100000),
        default=DEFAULT_REFINE,
        help=f"K: the reference levels have K and 2K times the shipped sub-steps "
        f"(default {DEFAULT_REFINE})",
    )
    p.add_argument(
        "--refine-grid",
        type=positive_int("refine-grid", 1, 1024),
        default=DEFAULT_GRID,
        help="G: the reference levels have G and 2G times the "
        f"shipped cells per contact radius (default {DEFAULT_GRID})",
    )
    for kind, what in (
        ("random", "uniform random actions"),
        (
            "bang-bang",
            "bang-bang actions, each tick a random corner of the action box (load down to "
            "N_min or up to N_max, full rolling rate and creep either way)",
        ),
        (
            "constant",
            "one action held throughout, drawn uniformly from the action box (rolling to "
            "the stroke's end, then the runner ringing on a stopped contact)",
        ),
    ):
        p.add_argument(
            f"--episodes-{kind}",
            type=positive_int(f"episodes-{kind}", 0, 100),
            default=1,
            help=f"episodes of {what} (default 1)",
        )
    p.add_argument(
        "--seed",
        type=positive_int("seed", 0, 2**31 - 1),
        default=0,
        help="reset seed of every episode and seed of the random, bang-bang and constant "
        "actions (default 0)",
    )
    p.add_argument(
        "--episode-steps",
        type=positive_int("episode-steps", 1, 10**6),
        default=None,
        help="episode length (default: the scene's own; shorter for a quick check)",
    )
    p.add_argument(
        "--variants",
        action="store_true",
        help="instead of each scene, its held-out variants: mu x0.5 and x2 where finite, "
        "runner mass x0.5 and x2, load x0.5 and x1.5 where there is one",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a scene key for every env of the run, the shipped one and the "
        "references (repeatable; e.g. --set F_ext=0.05 --set mu=inf): the accuracy of a "
        "scene of your own without writing its file",
    )
    p.add_argument(
        "--agents",
        default=None,
        metavar="RUNS",
        help="also an episode of each trained agent configuration: the seed-0 run's "
        "model.zip of every RUNS/<scene>/<config>_seed0 (e.g. results/agents)",
    )
    p.add_argument(
        "--out",
        type=file_path("out"),
        default=None,
        help="also write a markdown report to this file",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _command(args) -> str:
    """The command line that reproduces the run, for the report's header."""
    from shlex import quote

    parts = ["rolling-drive accuracy", "--all" if args.all else f"--scene {quote(args.scene)}"]
    from rolling_env.studies.accuracy import DEFAULT_GRID, DEFAULT_REFINE

    for flag, val, default in (
        ("--refine", args.refine, DEFAULT_REFINE),
        ("--refine-grid", args.refine_grid, DEFAULT_GRID),
        ("--episodes-random", args.episodes_random, 1),
        ("--episodes-bang-bang", args.episodes_bang_bang, 1),
        ("--episodes-constant", args.episodes_constant, 1),
        ("--seed", args.seed, 0),
        ("--episode-steps", args.episode_steps, None),
        ("--variants", args.variants, False),
        ("--agents", args.agents, None),
    ):
        if val is True:
            parts.append(flag)
        elif val != default:
            parts.append(f"{flag} {quote(str(val))}")
    parts += [f"--set {quote(kv)}" for kv in args.set]
    if args.out is not None:
        parts.append(f"--out {quote(str(args.out))}")
    return " ".join(parts)


def _run(args):
    from pathlib import Path

    from rolling_env.env.scenes import list_scenes, load_scene
    from rolling_env.io import check_writable, write_text
    from rolling_env.studies.accuracy import (
        agent_models,
        check_levels,
        check_scene,
        report,
        run,
        table,
    )

    scenes = list_scenes() if args.all else [args.scene]
    if args.agents is not None and not Path(args.agents).is_dir():
        raise ValueError(f"--agents: no such folder {args.agents!r}")
    keys = scene_keys(args.set, args.variants)
    if args.episode_steps is not None and "episode_steps" in keys:
        raise ValueError("--set: episode_steps is --episode-steps; give it once")
    base = None if args.episode_steps is None else {"episode_steps": args.episode_steps}
    overrides = {**keys, **(base or {})} or None
    changes = " ".join(f"{k}={v}" for k, v in _pairs(args.set)) or None
    # every scene and level is built once before any episode runs: a bad value fails at
    # once, naming its flag
    for scene in scenes:
        # the scene as given, then with the --set keys: an error names what caused it
        for flag, ov in (("scene", base), ("set", overrides))[: 2 if keys else 1]:
            try:
                check_scene(scene, ov)
            except ValueError as e:
                raise ValueError(f"--{flag}: {e}") from None
        for flag, factors in (
            ("refine", [(args.refine, 1), (2 * args.refine, 1)]),
            ("refine-grid", [(1, args.refine_grid), (1, 2 * args.refine_grid)]),
        ):
            try:
                check_levels(scene, factors, overrides)
            except ValueError as e:
                raise ValueError(f"--{flag}: {e}") from None
    models = {}
    if args.agents is not None:
        for scene in scenes:
            models[scene] = agent_models(args.agents, load_scene(scene).name)
    out = None if args.out is None else check_writable(args.out)
    res = run(
        scenes,
        models=models,
        variants=args.variants,
        refine=args.refine,
        grid=args.refine_grid,
        episodes_random=args.episodes_random,
        episodes_bang_bang=args.episodes_bang_bang,
        episodes_constant=args.episodes_constant,
        seed=args.seed,
        overrides=overrides,
        changes=changes,
    )
    human = "\n\n".join(table(r) for r in res["scenes"])
    if out is not None:
        write_text(out, report(res["scenes"], _command(args), res["seconds"]))
        human += f"\n\nwrote {out}"
    emit(res if args.all or args.variants else res["scenes"][0], args.json, human)
    return 0


def scene_keys(pairs, variants: bool = False) -> dict:
    """The scene keys of ``--set KEY=VALUE`` pairs, each value read as the scene file's loader
    reads it (``name`` and ``description`` as they are; the scene checks keys and ranges when
    it is built); a pair without ``=``, a key given twice, a value that is no YAML or
    ``--set`` with ``--variants`` (which scale the scene file's values) is a ValueError
    naming the flag."""
    import yaml

    from rolling_env.env.scenes import _UniqueKeyLoader

    out = {}
    for key, value in _pairs(pairs):
        if key in out:
            raise ValueError(f"--set: scene key {key!r} given twice")
        if key in ("name", "description"):
            out[key] = value
            continue
        try:
            out[key] = yaml.load(value, Loader=_UniqueKeyLoader)
        except yaml.YAMLError as e:
            msg = " ".join(str(e).split())
            raise ValueError(f"--set: the value of {key!r} is not valid YAML: {msg}") from None
    if out and variants:
        raise ValueError(
            "--set cannot be combined with --variants (the variants scale the scene file's values)"
        )
    return out


def _pairs(pairs) -> list[tuple[str, str]]:
    """(key, value) of each ``--set KEY=VALUE``, stripped; a pair without ``=``, key or value
    is a ValueError naming the flag."""
    out = []
    for kv in pairs:
        key, sep, value = (x.strip() for x in kv.partition("="))
        if not sep or not key:
            raise ValueError(f"--set must be KEY=VALUE (a scene key and its value), got {kv!r}")
        if not value:
            raise ValueError(f"--set: scene key {key!r} has no value (KEY=VALUE), got {kv!r}")
        out.append((key, value))
    return out
