"""Train a Stable-Baselines3 agent on a RollingDrive-v0 scene.

    python -m agents.train --algo ppo --scene default --seed 0 [--n-timesteps N] [--n-envs N]

Hyper-parameters come from ``configs/hyperparams/<algo>.yml`` (RL Zoo format, keyed by scene).
The run folder (default ``runs/<scene key>/<algo>_seed<seed>``, ``common.scene_key``: the
scene's name, a scene file's stem, or ``<stem>-<digest8>`` for a file named like a shipped
scene with other content) keeps config.yml (with the scene's fields and digest), command.txt,
meta.json (seed, package versions, env steps, wall time, git commit, thread settings, and
the vector env trained on: ``--vec-env auto``, the default, measures the batched env and a
DummyVecEnv of single envs for about a second and takes the faster), the TensorBoard log (tb/),
the EvalCallback log (evaluations.npz) and best model, periodic
checkpoints, and the final
model.zip with model_vecnormalize.pkl beside it.  Every file is written atomically; Ctrl-C or
SIGTERM saves a final checkpoint before exiting with 130 / 143 (128 + the signal).  A run
folder that already holds files is refused (``--overwrite`` replaces it, if it is a folder
this script created and holds only the files it writes: the new run is trained in
``<run>.overwrite`` beside it and replaces the earlier run only once it has finished; a
new run that is stopped or fails leaves the earlier run as it was and its own files, a
stopped run's checkpoint.zip among them, in ``<run>.overwrite``); there is no resume:
a stopped run keeps its checkpoint.zip, and a new run starts from scratch in another folder.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import shutil
import signal
import sys
import threading
import time
from pathlib import Path

import yaml

from rolling_env.cli.main import positive_int

from .common import (
    ALGOS,
    UsageError,
    atomic_write,
    buildable_scene,
    load_hyperparams,
    make_vec_env,
    save_model,
    scene_digest,
    scene_fields,
    scene_key,
)
from .hyperparams import action_noise, check_hyperparams, check_policy
from .residual import BASES as RESIDUAL_BASES
from .residual import SCALE_DEFAULT as RESIDUAL_SCALE
from .residual import ResidualVecEnv
from .run_folder import RUN_MARKER, _not_a_run, _replace_run, staging_folder
from .train_callbacks import _AtomicCheckpoint, _eval_callback, ticks_per_step
from .vec_choice import VEC_ENVS, choose_vec_env

SEED_MAX = 2**31 - 1 - 10_000  # the evaluation env is seeded seed + 10000
#: thread settings recorded in meta.json (none changes a transition; torch runs on one thread)
THREAD_VARS = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")


def source_commit() -> str | None:
    """The git commit of the code that trained (with "-dirty" where tracked files differ),
    None outside a git checkout or without git."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
        if head.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def build_parser():
    p = argparse.ArgumentParser(prog="python -m agents.train", description=__doc__.splitlines()[0])
    _add_run_args(p)
    _add_schedule_args(p)
    _add_env_args(p)
    return p


def _add_run_args(p) -> None:
    """The algorithm, scene, seed, budget, hyper-parameter file and run folder."""
    p.add_argument("--algo", choices=ALGOS, required=True)
    p.add_argument("--scene", default="default", help="scene name or YAML path")
    p.add_argument("--seed", type=positive_int("seed", 0, SEED_MAX), default=0)
    p.add_argument(
        "--n-timesteps",
        type=positive_int("n-timesteps", 1, 10**12),
        default=None,
        help="override the YAML budget",
    )
    p.add_argument(
        "--n-envs",
        type=positive_int("n-envs", 1, 4096),
        default=None,
        help="override the YAML n_envs",
    )
    p.add_argument("--conf", default=None, help="hyper-parameter YAML (default configs/...)")
    p.add_argument(
        "--run-dir",
        default=None,
        help="run folder (default runs/<scene key>/<algo>_seed<seed>); "
        "a folder that already holds files is refused unless --overwrite",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing run folder created by this script and holding "
        "only its files; the new run trains in <run-dir>.overwrite and replaces "
        "it only once finished (if stopped or failed, the earlier run is kept and "
        "the new run's files, its checkpoint.zip among them, stay in "
        "<run-dir>.overwrite)",
    )


def _add_schedule_args(p) -> None:
    """How often the run evaluates and saves checkpoints, and its progress bar."""
    p.add_argument(
        "--eval-freq",
        type=positive_int("eval-freq", 1, 10**12),
        default=10000,
        help="steps of the training env between evaluations (env steps; periods for "
        "--period-actions)",
    )
    p.add_argument("--eval-episodes", type=positive_int("eval-episodes", 1, 10**6), default=5)
    p.add_argument(
        "--checkpoint-freq",
        type=positive_int("checkpoint-freq", 1, 10**12),
        default=50000,
        help="steps of the training env between checkpoints (env steps; periods for "
        "--period-actions)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_env_args(p) -> None:
    """The training vector env, the residual or period-level action, and the env's threads."""
    p.add_argument(
        "--vec-env",
        choices=("auto",) + VEC_ENVS,
        default="auto",
        help="training vector env: the natively batched env, SB3's DummyVecEnv of "
        "single envs, or auto (default): whichever steps faster here, measured for "
        "about a second at start and recorded in meta.json (both give the same "
        "transitions)",
    )
    p.add_argument(
        "--residual",
        choices=sorted(RESIDUAL_BASES),
        default=None,
        help="train a residual policy: its action, times --residual-scale, is added "
        "to this baseline's (overrides the hyper-parameter entry's 'residual'; "
        "the run folder is named <algo>-residual_seed<N>)",
    )
    p.add_argument(
        "--residual-scale",
        type=float,
        default=None,
        help=f"how far the residual policy moves each action, in (0, 2] "
        f"(default: the entry's residual_scale, else {RESIDUAL_SCALE})",
    )
    p.add_argument(
        "--period-actions",
        action="store_true",
        default=None,
        help="one decision per excitation period: the policy's action is the next period's "
        "Eq. 32 working point (direction and force ratio, creep, stroke, force), played "
        "tick by tick (agents.period; overrides the entry's 'period_actions'; the run "
        "folder is named <algo>-period_seed<N>)",
    )
    p.add_argument(
        "--num-threads",
        type=num_threads_arg,
        default=None,
        help="numba threads of the batched env: auto (default: the serial or "
        "the threaded kernel, chosen step by step from measured step times) or "
        "1 (serial kernel) to NUMBA_NUM_THREADS",
    )


def num_threads_arg(text):
    """argparse type of --num-threads: 'auto' (None) or an integer in [1, NUMBA_NUM_THREADS]."""
    from rolling_env.env.threads import max_threads

    hi = max_threads()
    if text == "auto":
        return None
    try:
        x = int(text)
    except ValueError:
        x = 0
    if not 1 <= x <= hi:
        raise argparse.ArgumentTypeError(
            f"num-threads must be 'auto' or an integer in [1, {hi}], got {text!r}"
        )
    return x


def _wrap_actions(env, eval_env, checked: dict, hp: dict):
    """The training and evaluation envs wrapped for a residual policy (its action added to a
    baseline's) or a period-level one (a working point per period), and the entry as the
    run's config.yml records it."""
    residual = checked["residual"]
    if residual is not None:
        env = ResidualVecEnv(env, *residual)
        eval_env = ResidualVecEnv(eval_env, *residual)
        hp = dict(hp, residual=residual[0], residual_scale=residual[1])
    if checked["period_actions"]:
        from .period import PeriodVecEnv

        try:
            env, eval_env = PeriodVecEnv(env), PeriodVecEnv(eval_env)
        except ValueError as e:
            raise ValueError(f"--scene: {e}") from None
        hp = dict(hp, period_actions=True)
    return env, eval_env, hp


def _setup(args, command=None):
    """Hyper-parameters, envs (the scene checked) and the model; then the run folder with its
    config, so that a bad scene or hyper-parameter leaves nothing behind."""
    from stable_baselines3.common.utils import set_random_seed

    scene = args.scene
    try:  # the scene checked, and that it builds (a one-line error naming the flag if not)
        buildable_scene(scene)
    except ValueError as e:
        raise ValueError(f"--scene: {e}") from None
    key = scene_key(scene)
    hp, checked = _checked_entry(args, key)
    n_envs = args.n_envs if args.n_envs is not None else checked["n_envs"]
    n_timesteps = args.n_timesteps if args.n_timesteps is not None else checked["n_timesteps"]
    env_kwargs = checked["env_kwargs"]
    set_random_seed(args.seed)
    env, eval_env, trained, vec_env = _make_envs(args, n_envs, env_kwargs)
    env, eval_env, hp = _wrap_actions(env, eval_env, checked, hp)
    check_policy(args.algo, checked["kwargs"], env)  # torch's errors named policy_kwargs
    name = args.algo + (
        "-residual"
        if checked["residual"] is not None
        else "-period"
        if checked["period_actions"]
        else ""
    )
    run = Path(args.run_dir or f"runs/{key}/{name}_seed{args.seed}")
    work = _work_folder(run, args.overwrite)  # the run folder, or its staging folder
    model, eval_env = _make_model(args, checked, env, eval_env, work)
    work.mkdir(parents=True, exist_ok=True)  # an empty run folder is simply used
    atomic_write(
        work / RUN_MARKER,
        lambda p: Path(p).write_text("a run folder of agents.train: --overwrite may replace it\n"),
    )
    # what the run was trained on, for evaluate and rollout to check: the scene as given, its
    # key (runs/<key>/), and the checked scene's fields with their digest (a scene file's
    # stem alone does not say what was in it)
    cfg = dict(
        hp,
        n_envs=n_envs,
        n_timesteps=n_timesteps,
        algo=args.algo,
        scene=str(scene),
        seed=args.seed,
        env_kwargs=dict(env_kwargs, scene=str(scene)),
        scene_key=key,
        scene_digest=scene_digest(trained),
        scene_fields=scene_fields(trained),
    )
    atomic_write(work / "config.yml", lambda p: Path(p).write_text(yaml.safe_dump(cfg)))
    # as typed from the repository root (argv[0] is the module's file under python -m)
    command = command or "python -m agents.train " + shlex.join(sys.argv[1:])
    atomic_write(work / "command.txt", lambda p: Path(p).write_text(command + "\n"))
    return model, eval_env, run, work, n_envs, n_timesteps, trained, vec_env


def _checked_entry(args, key: str):
    """The hyper-parameter entry of the scene key ``key`` with the command line's overrides,
    and ``check_hyperparams``' result; a KeyError where no budget is given."""
    hp = load_hyperparams(args.algo, key, args.conf)
    if args.residual is not None:
        hp["residual"] = args.residual
    if args.residual_scale is not None:
        hp["residual_scale"] = args.residual_scale
    if getattr(args, "period_actions", None):
        hp["period_actions"] = True
    if args.n_timesteps is None and "n_timesteps" not in hp:
        raise KeyError("n_timesteps")
    return hp, check_hyperparams(args.algo, hp)  # every key used or refused, naming it


def _make_envs(args, n_envs: int, env_kwargs: dict):
    """The training vector env (of the kind ``--vec-env`` chooses), the evaluation env, the
    scene trained on (with the overrides of env_kwargs applied) and the vector env's record
    for meta.json."""
    scene = args.scene
    try:
        kind, vec_env = choose_vec_env(args.vec_env, scene, n_envs, env_kwargs, args.num_threads)
        env = make_vec_env(
            scene, n_envs, args.seed, env_kwargs, kind=kind, num_threads=args.num_threads
        )
    except ValueError as e:  # scene overrides in env_kwargs
        if "(randomize)" in str(e):  # --vec-env batched on a randomised scene
            raise ValueError(f"--vec-env batched: {e}") from None
        raise ValueError(f"hyper-parameter 'env_kwargs': {e}") from None
    trained = env.get_attr("scene", [0])[0]  # with the overrides of env_kwargs applied
    vec_env["num_threads"] = "auto" if args.num_threads is None else args.num_threads
    # single envs: their infos carry x*, the target and the slip work (for GOAL_LOG); the
    # transitions are those of the batched env
    eval_env = make_vec_env(scene, 1, args.seed + 10_000, env_kwargs, kind="dummy")
    return env, eval_env, trained, vec_env


def _work_folder(run: Path, overwrite: bool) -> Path:
    """The folder to train into: ``run``, or with ``overwrite`` a staging folder beside an
    earlier run that this script wrote (replaced once the new run has finished).  A
    UsageError, with nothing deleted, where a run folder holds files and cannot be replaced."""
    if not (run.is_symlink() or (run.exists() and (not run.is_dir() or any(run.iterdir())))):
        return run
    # a second run into the same folder would mix its files with the first's (and its
    # first checkpoint would overwrite an interrupted run's): refuse, keep what is there
    if not overwrite:
        raise UsageError(
            f"run folder {str(run)!r} already exists and is not empty: give "
            "another --run-dir or --seed, or --overwrite to replace it"
        )
    why = _not_a_run(run)
    if why:
        raise UsageError(
            f"--overwrite replaces only a run folder written by this script; "
            f"{str(run)!r} {why}: nothing was deleted"
        )
    work = staging_folder(run)  # the earlier run stays until the new one has finished
    if work.exists() or work.is_symlink():
        raise UsageError(
            f"--overwrite trains into {str(work)!r} first, and it exists "
            "(left by an interrupted or failed --overwrite run, with its "
            "checkpoint): move or delete it first; nothing was deleted"
        )
    return work


def _make_model(args, checked: dict, env, eval_env, work: Path):
    """The SB3 model on ``env`` (wrapped in VecNormalize where the entry normalises, the
    evaluation env too) logging to ``work/tb``; returns it and the evaluation env."""
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecNormalize

    norm = checked["normalize"]
    if norm is not None:
        env = VecNormalize(env, gamma=float(checked["kwargs"].get("gamma", 0.99)), **norm)
        eval_env = VecNormalize(
            eval_env, training=False, norm_reward=False, norm_obs=norm.get("norm_obs", True)
        )
    kwargs = dict(checked["kwargs"])
    kwargs.pop("policy_kwargs", None)
    if checked["action_noise"] is not None:
        kwargs["action_noise"] = action_noise(checked["action_noise"], env.action_space.shape[0])
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[args.algo]
    model = cls(
        checked["policy"],
        env,
        seed=args.seed,
        verbose=0,
        device="cpu",
        tensorboard_log=str(work / "tb"),
        policy_kwargs=checked["kwargs"].get("policy_kwargs"),
        **kwargs,
    )
    return model, eval_env


def train(args, *, command: str | None = None, on_eval=None) -> Path:
    """Train as the command line ``args`` (``build_parser().parse_args``) say and return the
    run folder.  ``command``: what command.txt records (default: this process's argv; a
    caller that trains in-process passes the equivalent ``agents.train`` command).
    ``on_eval(steps, mean_reward)`` is called after each periodic evaluation (steps of the
    training env, as ``n_timesteps`` counts them).  Ctrl-C and
    SIGTERM save a checkpoint (``Interrupted``) where this runs in the main thread; in another
    thread the caller handles signals."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList

    torch.set_num_threads(1)
    try:  # an error while learning is not a usage error: it propagates with its traceback
        model, eval_env, run, work, n_envs, n_timesteps, trained, vec_env = _setup(args, command)
    except KeyError as e:
        raise UsageError(
            f"hyper-parameter {e.args[0]!r} missing from {args.conf or 'configs/hyperparams'}"
        ) from e
    except (ValueError, TypeError, AssertionError, SyntaxError, OSError) as e:
        # bad scene, hyper-parameter (SB3 asserts its own), unreadable --conf
        raise UsageError(
            f"{type(e).__name__}: {e}" if not isinstance(e, ValueError) else str(e)
        ) from e
    callbacks = CallbackList(
        [
            _eval_callback(
                eval_env,
                work,
                max(args.eval_freq // n_envs, 1),
                args.eval_episodes,
                on_eval,
                trained.tolerance,
            ),
            _AtomicCheckpoint.make(work, max(args.checkpoint_freq, 1)),
        ]
    )
    interrupted, signum, wall = _learn(model, n_timesteps, callbacks, args, run, work)
    save_model(model, model.get_vec_normalize_env(), work, "checkpoint" if interrupted else "model")
    meta = _meta(args, model, eval_env, trained, n_envs, wall, interrupted, vec_env)
    atomic_write(work / "meta.json", lambda p: Path(p).write_text(json.dumps(meta, indent=1)))
    print(json.dumps(meta))
    if interrupted:  # saved, but not finished: the shell convention 128 + signal number
        raise Interrupted(128 + signum, work, run if work != run else None)
    if work != run:
        _replace_run(run, work)
    return run


def _learn(model, n_timesteps: int, callbacks, args, run: Path, work: Path):
    """``model.learn`` with SIGTERM (where this runs in the main thread) and Ctrl-C taken as
    a stop; returns whether it was stopped, the signal that stopped it (SIGINT when none
    was received) and the wall seconds."""
    received = []

    def on_term(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt

    main_thread = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGTERM, on_term) if main_thread else None  # main thread only
    t0 = time.perf_counter()
    interrupted = False
    try:
        model.learn(
            n_timesteps,
            callback=callbacks,
            progress_bar=not args.no_progress,
            tb_log_name=args.algo,
        )
    except KeyboardInterrupt:
        interrupted = True
    except BaseException:
        if work != run:
            print(
                f"python -m agents.train: the earlier run in {str(run)!r} is kept; this "
                f"run's files are in {str(work)!r}",
                file=sys.stderr,
            )
        raise
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, old)
        shutil.rmtree(work / ".eval_scratch", ignore_errors=True)
    wall = time.perf_counter() - t0
    return interrupted, (received[0] if received else signal.SIGINT), wall


def _meta(args, model, eval_env, trained, n_envs, wall, interrupted, vec_env) -> dict:
    """meta.json of a run: what was trained, how long, and with which code and machine."""
    import stable_baselines3 as sb3
    import torch

    import rolling_env

    scene = args.scene
    return {
        "algo": args.algo,
        "scene": str(scene),
        "scene_key": scene_key(scene),
        "scene_digest": scene_digest(trained),
        "seed": args.seed,
        "env_steps": int(model.num_timesteps) * ticks_per_step(eval_env),
        "decisions": int(model.num_timesteps),  # steps of the training env (periods or ticks)
        "wall_seconds": wall,
        "interrupted": interrupted,
        "n_envs": n_envs,
        "rolling_drive": rolling_env.__version__,
        "stable_baselines3": sb3.__version__,
        "torch": torch.__version__,
        "python": platform.python_version(),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPU cores, no GPU",
        "commit": source_commit(),
        "threads": {k: os.environ.get(k) for k in THREAD_VARS},
        "vec_env": vec_env,
    }


class Interrupted(Exception):
    """Training stopped by SIGINT/SIGTERM after its checkpoint was saved; args: the exit code,
    the folder holding checkpoint.zip, and the earlier run kept (--overwrite) or None."""


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        train(args)
    except UsageError as e:  # a bad scene or hyper-parameter: one line, exit 2, no run folder
        print(f"python -m agents.train: error: {e}", file=sys.stderr)
        return 2
    except Interrupted as e:  # checkpoint saved; a scheduler must not take the run as done
        code, work, kept = e.args
        print(
            f"python -m agents.train: interrupted; checkpoint.zip saved in {str(work)!r}"
            + (f" (the earlier run in {str(kept)!r} is kept)" if kept else ""),
            file=sys.stderr,
        )
        return code
    return 0


if __name__ == "__main__":
    sys.exit(main())
