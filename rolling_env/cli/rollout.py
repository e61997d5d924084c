"""Subcommand rollout: one episode of a controller in a scene -> CSV + PNG (+ optional frame)."""

from __future__ import annotations

from pathlib import Path

from rolling_env.cli.main import emit, finite_float, folder_path, positive_int


def register(sub):
    p = sub.add_parser(
        "rollout",
        help="roll out a controller in a scene, write CSV and a plot",
        description="Run one episode of RollingDrive-v0 with a controller and "
        "write the trajectory to CSV and a PNG plot.",
    )
    p.add_argument("--scene", default="default", help="scene name or YAML path (default: default)")
    p.add_argument(
        "--controller",
        default="eq32-feedback",
        help="random | zero | eq32 (also eq32-open-loop, its name in "
        "agents.evaluate's tables) | eq32-feedback | path/to/model.zip",
    )
    p.add_argument("--seed", type=positive_int("seed", 0, 2**31 - 1), default=0)
    p.add_argument(
        "--target",
        type=finite_float("target"),
        default=None,
        help="target displacement [m] (default: drawn from the scene's range with the seed)",
    )
    p.add_argument(
        "--out",
        type=folder_path("out"),
        default="results/rollouts",
        help="output folder (default results/rollouts, relative to the current directory)",
    )
    p.add_argument("--frame", action="store_true", help="also save the final rendered frame")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_run)


def _run(args):
    import rolling_env
    from rolling_env.env.drive_env import target_option
    from rolling_env.env.rollout import controller_label, make_controller, plot, rollout, write_csv

    try:
        env = rolling_env.make(args.scene, render_mode="rgb_array" if args.frame else None)
    except ValueError as e:  # an unknown scene or a bad scene file
        raise ValueError(f"--scene: {e}") from None
    asked = None if args.target is None else {"target": args.target}
    try:  # the scene's target range, named as the argument the user gave
        target_option(env.unwrapped.scene, asked)
    except ValueError as e:
        raise ValueError(str(e).replace("options['target']", "--target")) from None
    ctrl = make_controller(args.controller, env, seed=args.seed, scene=args.scene)
    from rolling_env.io import check_writable

    check_writable(args.out, folder=True)
    data = rollout(env, ctrl, seed=args.seed, target=args.target)
    # files named by the scene's key (agents' run folders and tables use it too), not by the
    # name inside the YAML: a copy of default.yaml with other values keeps "name: default"
    # and would overwrite the shipped scene's rollout
    from rolling_env.env.scenes import scene_key

    key = scene_key(args.scene)
    stem = f"{key}_{controller_label(args.controller)}_seed{args.seed}"
    out = Path(args.out)
    from rolling_env.io import atomic_write, staged

    with staged():  # the CSV, its plot (and the frame) all new, or none of them
        csv_path = write_csv(data, out / f"{stem}.csv")
        png_path = plot(data, out / f"{stem}.png", title=f"{key}: {args.controller}")
        res = {
            "csv": str(csv_path),
            "png": str(png_path),
            "return": data["return"],
            "final_error": data["final_error"],
            "target": float(data["target"][-1]),
            "slip_work": data["total_slip_work"],
            "steps": int(data["step"][-1]),
        }
        if args.frame:
            import matplotlib.image

            frame_path = out / f"{stem}_frame.png"
            frame = env.render()
            atomic_write(frame_path, lambda p: matplotlib.image.imsave(p, frame, format="png"))
            res["frame"] = str(frame_path)
    env.close()
    emit(res, args.json, "\n".join(f"{k}: {v}" for k, v in res.items()))
    return 0
