"""agents.evaluate and the rollout of trained models: the goal and seed verdicts, which runs are
evaluated on which scene (and which are refused or marked), damaged files, bounds."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import rolling_env
from agents.baselines import Eq32OpenLoop
from agents.loading import load_agent
from agents.verdicts import goal_verdicts
from rolling_env.env.rollout import rollout
from tests.train_argv import tiny_ppo_argv


def _eval_argv(*scenes, out, runs=None, episodes=1, extra=()):
    """The command line of agents.evaluate for ``scenes`` (names or paths), without ``--runs``
    where ``runs`` is None, ending in ``extra``."""
    runs_args = [] if runs is None else ["--runs", str(runs)]
    return [
        "--scenes",
        *map(str, scenes),
        *runs_args,
        "--episodes",
        str(episodes),
        "--out",
        str(out),
        *extra,
    ]


def test_time_to_goal_is_the_first_evaluation_that_meets_the_goal():
    from agents.verdicts import time_to_goal

    base = {"final_abs_error_mean": 1.0e-8, "slip_work_mean": 2.0e-8}
    log = [
        {
            "env_steps": 10,
            "wall_seconds": 1.0,
            "final_abs_error": [4e-9, 8e-9],
            "slip_work": [1e-8, 1e-8],
        },  # error 0.6x: not yet
        {
            "env_steps": 20,
            "wall_seconds": 2.0,
            "final_abs_error": [4e-9, 5e-9],
            "slip_work": [3e-8, 2e-8],
        },  # error 0.45x, but 1.25x the wear
        {
            "env_steps": 30,
            "wall_seconds": 3.5,
            "final_abs_error": [4e-9, 6e-9],
            "slip_work": [2e-8, 2e-8],
        },  # 0.5x at 1x: met
        {"env_steps": 40, "wall_seconds": 4.0, "final_abs_error": [1e-9], "slip_work": [1e-8]},
    ]
    assert time_to_goal(log, base) == (30, 3.5)
    assert time_to_goal(log[:2], base) == "never"
    assert time_to_goal(None, base) is None


def test_goal_verdicts():
    rows = [
        dict(scene="s", controller="eq32-open-loop", final_abs_error_mean=4.0, slip_work_mean=1.0),
        dict(scene="s", controller="eq32-feedback", final_abs_error_mean=2.0, slip_work_mean=3.0),
        dict(scene="s", controller="ppo_seed0", final_abs_error_mean=0.9, slip_work_mean=3.0),
        dict(scene="s", controller="sac_seed0", final_abs_error_mean=0.9, slip_work_mean=3.1),
    ]
    v = {r["agent"]: r for r in goal_verdicts(rows)}
    assert v["ppo_seed0"]["baseline"] == "eq32-feedback" and v["ppo_seed0"]["met"]
    assert not v["sac_seed0"]["met"], "more slip work than the baseline is not the goal"


def test_seed_summary_sums_up_runs_that_differ_only_in_their_seed():
    """ppo_seed0..2 are one configuration over three seeds: the mean of the runs' means, their
    range, and the goal met in 2 of 3 (seed 2 has more slip work than the baseline); sac_seed0
    alone and a run not named <name>_seed<N> get no summary row."""
    from agents.report import seed_summary

    def row(c, err, slip):
        return dict(
            scene="s",
            controller=c,
            final_abs_error_mean=err * 1e-8,
            slip_work_mean=slip,
            tolerance=1e-8,
        )

    rows = [
        row("eq32-open-loop", 4.0, 1.0),
        row("eq32-feedback", 2.0, 3.0),
        row("ppo_seed0", 0.5, 2.0),
        row("ppo_seed1", 0.9, 3.0),
        row("ppo_seed2", 1.0, 4.0),
        row("sac_seed0", 0.1, 0.0),
        row("myrun", 0.1, 0.0),
    ]
    (g,) = seed_summary(rows)
    assert (g["agent"], g["seeds"], g["seed_list"]) == ("ppo", 3, [0, 1, 2]), g
    assert g["error_mean"] == pytest.approx(0.8, rel=1e-12), g
    assert (g["error_min"], g["error_max"]) == pytest.approx((0.5, 1.0), rel=1e-12), g
    assert g["slip_mean"] == pytest.approx(3.0, rel=1e-12), g
    assert (g["met"], g["judged"]) == (2, 3), f"goal met in seeds 0 and 1 only: {g}"
    # two runs naming one seed (ppo_seed1, ppo_seed01) are not two seeds
    assert seed_summary(rows + [row("ppo_seed01", 0.7, 2.0)]) == []
    # an interrupted run (its checkpoint, fewer steps) or another configuration is not a seed
    for key, value in (
        ("model_file", "checkpoint.zip"),
        ("train_env_steps", 20_000),
        ("config_key", '{"n_timesteps": 1000}'),
    ):
        other = [dict(r, **{key: value}) if r["controller"] == "ppo_seed1" else r for r in rows]
        assert seed_summary(other) == [], f"runs with another {key} were summed up over seeds"


def test_rollout_takes_the_open_loop_baseline_by_its_table_name():
    """``eq32-open-loop`` (the name in agents.evaluate's tables) is the same controller as
    ``eq32``: the same class and an identical 40-step rollout."""
    from rolling_env.env.rollout import make_controller

    data = {}
    for name in ("eq32", "eq32-open-loop"):
        env = rolling_env.make("default")
        ctrl = make_controller(name, env)
        assert isinstance(ctrl, Eq32OpenLoop), f"{name}: {type(ctrl).__name__}"
        data[name] = rollout(env, ctrl, seed=5, max_steps=40)
    a, b = data["eq32"], data["eq32-open-loop"]
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=k)


def test_evaluate_checks_every_scene_before_writing(tmp_path, capsys):
    from agents.evaluate import main as evaluate_main

    with pytest.raises(SystemExit) as e:
        evaluate_main(
            _eval_argv("heavy_inf_friction", "bogus", runs=tmp_path, out=tmp_path / "out")
        )
    assert e.value.code == 2 and "bogus" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_evaluate_rejects_a_scene_the_baselines_cannot_drive(tmp_path, capsys):
    """A valid scene file that Eq. 32 cannot drive (w < 2) is refused before anything is
    written, not after the other scenes were evaluated."""
    from agents.evaluate import main as evaluate_main

    slow = tmp_path / "slow.yaml"
    data = yaml.safe_load((rolling_env.env.scenes.SCENE_DIR / "default.yaml").read_text())
    slow.write_text(yaml.safe_dump({**data, "omega_R_max": 0.1}))
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv("heavy_inf_friction", slow, runs=tmp_path, out=tmp_path / "out"))
    assert e.value.code == 2 and "omega_R_max" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """One tiny PPO run on a scene *file* (copy of heavy_inf_friction named 'myscene')."""
    from agents.train import main as train_main

    base = tmp_path_factory.mktemp("evalruns")
    scene = base / "scenes" / "myscene.yaml"
    scene.parent.mkdir()
    scene.write_text((rolling_env.env.scenes.SCENE_DIR / "heavy_inf_friction.yaml").read_text())
    runs = base / "runs"
    assert (
        train_main(
            tiny_ppo_argv("--scene", str(scene), "--run-dir", str(runs / "myscene" / "ppo_seed0"))
        )
        == 0
    )
    return scene, runs


def test_evaluate_finds_the_runs_of_a_scene_file(trained_run, tmp_path):
    """A scene given as a file: its runs live under <runs>/<stem>/ (where train puts them) and
    its plot goes to <out>/plots/<stem>.png, not beside the scene file."""
    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    out = tmp_path / "out"
    assert evaluate_main(_eval_argv(scene, runs=runs, out=out)) == 0
    text = (out / "comparison.csv").read_text()
    assert "ppo_seed0" in text, f"the trained agent was not evaluated:\n{text}"
    assert (out / "plots" / "myscene.png").exists()
    assert sorted(p.name for p in scene.parent.iterdir()) == ["myscene.yaml"]


def test_evaluate_model_choice_and_seed_summary(trained_run, tmp_path, capsys):
    """--model final (the default) evaluates model.zip and --model best best_model.zip, and the
    table names the file of each row; two seeds of one configuration get an "Over seeds"
    row (here the same model twice: its range is one value).  A run folder without a model
    (an interrupted run whose checkpoint was not copied) is named in a warning, not dropped
    silently; run folders are listed in the order of their numbers (seed 2 before 10)."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from agents.loading import scene_runs

    scene, runs = trained_run
    mine = tmp_path / "runs"
    shutil.copytree(runs, mine)
    shutil.copytree(mine / "myscene" / "ppo_seed0", mine / "myscene" / "ppo_seed1")
    (mine / "myscene" / "ppo_seed10").mkdir()
    shutil.copy(mine / "myscene" / "ppo_seed0" / "config.yml", mine / "myscene" / "ppo_seed10")
    assert [p.name for p in scene_runs(str(scene), mine)] == [
        "ppo_seed0",
        "ppo_seed1",
        "ppo_seed10",
    ]
    for model, name in (("final", "model.zip"), ("best", "best_model.zip")):
        out = tmp_path / model
        extra = [] if model == "final" else ["--model", model]
        assert evaluate_main(_eval_argv(scene, runs=mine, out=out, episodes=2, extra=extra)) == 0
        err = capsys.readouterr().err
        assert "ppo_seed10 has no model" in err and "not evaluated" in err, err
        with open(out / "comparison.csv") as f:
            rows = {r["controller"]: r for r in csv.DictReader(f)}
        assert rows["ppo_seed0"]["model_file"] == name, f"--model {model}: {rows['ppo_seed0']}"
        md = (out / "comparison.md").read_text()
        assert f"| myscene | ppo_seed1 | {name} |" in md, md
        (line,) = [ln for ln in md.splitlines() if ln.startswith("| myscene | ppo | 0, 1 |")]
        e0 = float(rows["ppo_seed0"]["final_abs_error_mean"]) / float(
            rows["ppo_seed0"]["tolerance"]
        )
        assert f"| {e0:.2f} ({e0:.2f}-{e0:.2f}) |" in line, f"mean and range of one value: {line}"


@pytest.mark.parametrize(
    "edit,match",
    [
        (
            lambda c: c.update(env_kwargs={"scene": "x", "mu": 0.02}),
            r"scene overrides \{'mu': 0.02\}",
        ),
        (
            lambda c: c.update(scene="resonant", scene_key="resonant"),
            "was trained on scene 'resonant'",
        ),
        (
            lambda c: (c.update(scene="resonant"), c.pop("scene_key")),  # a run from before the key
            "was trained on scene 'resonant'",
        ),
    ],
)
def test_evaluate_refuses_runs_not_trained_on_the_scene(trained_run, tmp_path, capsys, edit, match):
    """A run trained with scene overrides, or on another scene, is refused (naming it) before
    any episode runs or any file is written; it was reported as if trained on the plain
    scene."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    mine = tmp_path / "runs" / "myscene"
    shutil.copytree(runs / "myscene", mine)
    cfg_path = mine / "ppo_seed0" / "config.yml"
    cfg = yaml.safe_load(cfg_path.read_text())
    edit(cfg)
    cfg_path.write_text(yaml.safe_dump(cfg))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv(scene, runs=tmp_path / "runs", out=out))
    assert e.value.code == 2
    assert len(__import__("re").findall(match, capsys.readouterr().err)) == 1
    assert not [p for p in out.rglob("*") if p.is_file()], "files written before the check"


def test_mismatched_model_and_statistics_are_refused(trained_run, tmp_path, capsys):
    """A model and VecNormalize statistics saved at different steps (a kill between the two
    writes of save_model) are refused by load_agent, naming both files; evaluate then falls
    back to the run's next model, with a warning."""
    import shutil

    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.common import SAVED_AT
    from agents.evaluate import controllers_for

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    for f in run.glob("best_model*"):
        f.unlink()
    env = rolling_env.make(str(scene))
    load_agent(run / "model.zip", env)  # a consistent pair loads
    shutil.copy(run / "model.zip", run / "checkpoint.zip")  # a consistent fallback
    shutil.copy(run / "model_vecnormalize.pkl", run / "checkpoint_vecnormalize.pkl")
    stats = run / "model_vecnormalize.pkl"
    vn = VecNormalize.load(str(stats), DummyVecEnv([lambda: rolling_env.make(str(scene))]))
    setattr(vn, SAVED_AT, getattr(vn, SAVED_AT) + 1)  # as if saved one step later
    vn.save(str(stats))
    with pytest.raises(ValueError, match="model_vecnormalize.pkl was saved at step"):
        load_agent(run / "model.zip", env)
    ctrls = controllers_for(str(scene), tmp_path / "runs", env)
    assert ctrls["ppo_seed0"].file == "checkpoint.zip"
    assert "trying checkpoint.zip" in capsys.readouterr().err
    (run / "checkpoint.zip").unlink()
    with pytest.raises(ValueError, match="model_vecnormalize.pkl was saved at step"):
        controllers_for(str(scene), tmp_path / "runs", env)  # nothing left to fall back to


def _scene_file(path, base="default", **changes):
    data = yaml.safe_load((rolling_env.env.scenes.SCENE_DIR / f"{base}.yaml").read_text())
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump({**data, **changes}))
    return path


def test_custom_scene_file_named_like_a_shipped_one_is_not_taken_for_it(
    tmp_path, monkeypatch, capsys
):
    """A scene file named default.yaml with other content (mu 0.01, runner_mass 1e-4) was
    trained into runs/default/, recorded as env_kwargs {scene: default} and evaluated as a
    `default` agent: it gets its own key default-<digest8>, its config records the scene's
    fields and digest, and evaluate refuses it on the shipped default (by key, and by
    content where the key was edited by hand)."""
    import shutil

    from agents.common import scene_digest, scene_key
    from agents.evaluate import main as evaluate_main
    from agents.train import main as train_main

    custom = _scene_file(tmp_path / "mine" / "default.yaml", mu=0.01, runner_mass=1e-4)
    key = scene_key(str(custom))
    assert key == f"default-{scene_digest(custom)[:8]}", key
    assert scene_key(str(rolling_env.env.scenes.SCENE_DIR / "default.yaml")) == "default", (
        "the shipped file itself keeps its name"
    )
    monkeypatch.chdir(tmp_path)
    assert train_main(tiny_ppo_argv("--scene", str(custom))) == 0
    assert not (tmp_path / "runs" / "default").exists(), "landed in runs/default/ silently"
    run = tmp_path / "runs" / key / "ppo_seed0"
    cfg = yaml.safe_load((run / "config.yml").read_text())
    assert cfg["scene_key"] == key and cfg["scene_digest"] == scene_digest(custom), cfg
    assert cfg["scene_fields"]["mu"] == 0.01 and cfg["scene_fields"]["runner_mass"] == 1e-4
    assert cfg["env_kwargs"] == {"scene": str(custom)}, (
        f"config.yml must name the scene file trained on, got {cfg['env_kwargs']}"
    )
    shutil.copytree(run, tmp_path / "runs" / "default" / "ppo_seed0")  # moved by hand
    argv = _eval_argv("default", runs=tmp_path / "runs", out=tmp_path / "out")
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and f"was trained on scene {key!r}" in err, err
    moved = tmp_path / "runs" / "default" / "ppo_seed0" / "config.yml"
    moved.write_text(yaml.safe_dump(dict(cfg, scene_key="default")))  # the key edited too
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "mu 0.01 vs 0.2" in err, err
    assert not (tmp_path / "out" / "comparison.csv").exists()


def test_evaluate_refuses_a_run_whose_scene_file_changed(trained_run, tmp_path, capsys):
    """The scene file a run was trained on, edited afterwards (same stem, same folder
    layout): refused naming the key that changed, not evaluated as if trained on it."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    shutil.copytree(runs, tmp_path / "runs")
    edited = _scene_file(
        tmp_path / "scenes" / "myscene.yaml", base="heavy_inf_friction", runner_mass=0.01
    )
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv(edited, runs=tmp_path / "runs", out=tmp_path / "out"))
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "runner_mass" in err, err


def _as_if_trained_on(run, **changes):
    """Rewrite a run's config.yml as agents.train would have written it on the scene with
    ``changes`` to its recorded fields (a key given as None left out, as a run recorded
    before the key existed): fields and their digest."""
    from agents.common import fields_digest

    cfg_path = run / "config.yml"
    cfg = yaml.safe_load(cfg_path.read_text())
    fields = dict(cfg["scene_fields"])
    for k, v in changes.items():
        if v is None:
            fields.pop(k, None)
        else:
            fields[k] = v
    cfg.update(scene_fields=fields, scene_digest=fields_digest(fields))
    cfg_path.write_text(yaml.safe_dump(cfg))
    return cfg


def test_numerics_of_a_recorded_scene_are_completed_and_described():
    """A run recorded before a scene key existed (``accuracy``, ``n_sub``, ``grid_levels``) is
    read with the value in effect then (the key's default; the recorded sub_steps for n_sub;
    one fixed grid, 0 levels): no difference where nothing else changed; the note names what
    differs in the numerics, the resolved sub-steps too; the shipped scenes record the
    sub-steps they resolve to."""
    from agents.common import completed_fields, numerics_note, scene_fields

    now = scene_fields("light_stiff")
    n = rolling_env.env.scenes.load_scene("light_stiff").n_sub
    assert now["sub_steps"] == "auto" and now["n_sub"] == n and now["accuracy"] == 0.01, now
    assert now["resolution"] == 128, "the notes below assume 128 cells per radius"
    assert now["grid_levels"] == 4, "the notes below assume 4 grid levels"
    old = {k: v for k, v in now.items() if k not in ("accuracy", "n_sub")}
    before_levels = {k: v for k, v in old.items() if k != "grid_levels"}
    assert completed_fields(dict(before_levels, sub_steps="auto"))["grid_levels"] == 0
    assert (
        numerics_note(completed_fields(dict(before_levels, sub_steps="auto", n_sub=n)), now)
        == "grid_levels 0 (now 4)"
    )
    assert completed_fields(dict(old, sub_steps="auto"))["accuracy"] == 0.01
    assert numerics_note(completed_fields(dict(old, sub_steps=8)), now) == (
        f"sub_steps 8 (now auto: {n})"
    )
    assert numerics_note(completed_fields(dict(now)), now) == ""
    assert numerics_note(
        completed_fields(dict(old, sub_steps=n + 1, resolution=32.0, accuracy=0.05)), now
    ) == (f"sub_steps {n + 1} (now auto: {n}), resolution 32 (now 128), accuracy 0.05 (now 0.01)")


def test_a_run_trained_on_other_numerics_is_evaluated_and_marked(trained_run, tmp_path, capsys):
    """A run whose recorded scene differs from the evaluated one only in its numerics
    (sub_steps, resolution, accuracy; recorded before accuracy and n_sub existed, as the
    committed runs were) is evaluated as it is, and every place that reports it says so:
    a warning, the CSV's trained_numerics, a footnote mark in the three tables with the note
    under the first, and the plot's legend.  `rolling-drive rollout` takes its model too."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from rolling_env.cli.main import main as cli_main

    scene, runs = trained_run
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "ppo_seed0")
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "ppo_seed1")
    for seed in (0, 1):
        _as_if_trained_on(
            tmp_path / "runs" / "myscene" / f"ppo_seed{seed}",
            sub_steps=4,
            resolution=12.0,
            accuracy=None,
            n_sub=None,
        )
    sc = rolling_env.env.scenes.load_scene(str(scene))
    assert sc.sub_steps == "auto" and sc.n_sub != 4 and sc.resolution != 12
    assert sc.accuracy == 0.01, "the note below assumes the default accuracy the runs recorded"
    out = tmp_path / "out"
    assert evaluate_main(_eval_argv(scene, runs=tmp_path / "runs", out=out)) == 0
    note = f"sub_steps 4 (now auto: {sc.n_sub}), resolution 12 (now {sc.resolution:g})"
    err = capsys.readouterr().err
    assert err.count("trained on other numerics or reward weights") == 2 and note in err, err
    with open(out / "comparison.csv") as f:
        rows = {r["controller"]: r for r in csv.DictReader(f)}
    assert rows["ppo_seed0"]["trained_numerics"] == note, rows["ppo_seed0"]
    assert rows["eq32-feedback"]["trained_numerics"] == "", "a baseline is never marked"
    md = (out / "comparison.md").read_text()
    assert "| myscene | ppo_seed0 [1] | model.zip |" in md, md
    assert f"* [1] trained on other numerics or reward weights: {note}\n" in md, md
    assert "| myscene | ppo_seed1 [1] | eq32-open-loop |" in md, "goal table not marked"
    assert "| myscene | ppo [1] | 0, 1 |" in md, "seed summary not marked"
    assert "| myscene | eq32-feedback | - |" in md
    assert (out / "plots" / "myscene.png").stat().st_size > 0
    model = tmp_path / "runs" / "myscene" / "ppo_seed0" / "model.zip"
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                str(scene),
                "--controller",
                str(model),
                "--out",
                str(tmp_path / "roll"),
                "--json",
            ]
        )
        == 0
    )
    assert "trained on other numerics" in capsys.readouterr().err


def test_a_run_trained_with_other_reward_weights_is_evaluated_and_marked(
    trained_run, tmp_path, capsys
):
    """The reward's weights shape learning, not what the comparison scores: a run trained
    with ``w_final`` in its env_kwargs (and so in its recorded fields) is evaluated on the
    plain scene and its note names the weight."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    cfg = _as_if_trained_on(run, w_final=10.0)
    (run / "config.yml").write_text(
        yaml.safe_dump(dict(cfg, env_kwargs=dict(cfg["env_kwargs"], w_final=10.0)))
    )
    out = tmp_path / "out"
    assert evaluate_main(_eval_argv(scene, runs=tmp_path / "runs", out=out)) == 0
    md = (out / "comparison.md").read_text()
    assert "* [1] trained on other numerics or reward weights: w_final 10 (now 0)\n" in md, md
    assert "| myscene | ppo_seed0 [1] | model.zip |" in md, md
    capsys.readouterr()


@pytest.mark.parametrize(
    "changes,names",
    [
        ({"sub_steps": 4, "mu": 0.3}, ["mu 0.3 vs inf", "sub_steps 4 vs 'auto'"]),  # physics too
        ({"resolution": 12.0, "episode_steps": 256}, ["episode_steps 256 vs 512"]),  # the task
        ({"resolution": 12.0, "ticks_per_period": 16}, ["ticks_per_period 16 vs 8"]),
    ],
)
def test_a_run_trained_on_other_physics_or_task_stays_refused(
    trained_run, tmp_path, capsys, changes, names
):
    """A recorded scene that differs in a physics or task key is refused as before (exit 2,
    the keys named with the physics first, nothing written), also where its numerics differ
    too; so is a record whose fields do not reproduce its digest (edited by hand: its fields
    cannot be trusted key by key)."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    cfg = _as_if_trained_on(run, **changes)
    argv = _eval_argv(scene, runs=tmp_path / "runs", out=tmp_path / "out")
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err and "not comparable" in err, err
    assert "trained on other numerics" not in err, err
    trained_vs_now = err.split("trained vs now: ")[1]
    for n in names:
        assert n in trained_vs_now, err
    numerics_key = "resolution" if "resolution" in changes else "sub_steps"
    assert trained_vs_now.index(names[0]) < trained_vs_now.index(numerics_key), err
    assert not (tmp_path / "out" / "comparison.csv").exists()
    # numerics only, but the digest is not that of the recorded fields: refused
    (run / "config.yml").write_text(
        yaml.safe_dump(
            dict(
                cfg,
                scene_fields={
                    k: v
                    for k, v in cfg["scene_fields"].items()
                    if k not in changes or k in ("sub_steps", "resolution")
                },
            )
        )
    )
    with pytest.raises(SystemExit) as e:
        evaluate_main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "content differs" in err, err


def test_rollout_cli_refuses_a_model_of_another_scene_and_names_files_by_run(
    trained_run, tmp_path, capsys
):
    """`rolling-drive rollout --controller <run>/model.zip --scene X` refuses a model whose
    run was trained on other scene content (exit 2, one line); a copy of the scene under
    another name is the same scene.  Output files are named from the run folder: two runs'
    model.zip no longer write the same <scene>_model_seed0.csv."""
    import shutil

    from rolling_env.cli.main import main as cli_main

    scene, runs = trained_run
    model = runs / "myscene" / "ppo_seed0" / "model.zip"
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                "default",
                "--controller",
                str(model),
                "--out",
                str(tmp_path / "out"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("rolling-drive rollout: error:") and err.count("\n") == 1, err
    assert "content differs" in err and "mu" in err, err
    other = tmp_path / "runs" / "sac_seed0"
    shutil.copytree(model.parent, other)
    for m in (model, other / "model.zip"):
        assert (
            cli_main(
                [
                    "rollout",
                    "--scene",
                    "heavy_inf_friction",
                    "--controller",
                    str(m),
                    "--out",
                    str(tmp_path / "out"),
                    "--json",
                ]
            )
            == 0
        ), capsys.readouterr()
    names = sorted(p.name for p in (tmp_path / "out").glob("*.csv"))
    assert names == [
        "heavy_inf_friction_ppo_seed0-model_seed0.csv",
        "heavy_inf_friction_sac_seed0-model_seed0.csv",
    ], names


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_a_loose_model_zip_is_loaded_with_its_own_algorithm(algo, tmp_path, capsys):
    """A model .zip without its run's config.yml was loaded as PPO (a loose SAC zip gave a
    traceback): the algorithm is read from the zip, and the missing VecNormalize statistics
    are warned about; the rollout CLI runs it."""
    import stable_baselines3 as sb3

    from agents.loading import model_algo
    from rolling_env.cli.main import main as cli_main
    from rolling_env.env.sb3_vec import RollingDriveVecEnv

    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
    path = tmp_path / "loose" / f"{algo}_model.zip"
    path.parent.mkdir()
    cls(
        "MlpPolicy",
        RollingDriveVecEnv(1),
        device="cpu",
        **({"buffer_size": 100} if algo != "ppo" else {}),
    ).save(path)
    assert model_algo(path) == algo
    agent = load_agent(path, rolling_env.make("default"))
    assert type(agent.model) is cls, f"loaded as {type(agent.model).__name__}"
    assert f"has no {algo}_model_vecnormalize.pkl beside it" in capsys.readouterr().err
    assert (
        cli_main(
            [
                "rollout",
                "--scene",
                "default",
                "--controller",
                str(path),
                "--out",
                str(tmp_path / "out"),
                "--json",
            ]
        )
        == 0
    )
    assert (tmp_path / "out" / f"default_loose-{algo}_model_seed0.csv").exists()


def test_a_zip_that_is_no_sb3_model_is_one_line(tmp_path, capsys):
    import zipfile

    from agents.loading import model_algo
    from rolling_env.cli.main import main as cli_main

    junk = tmp_path / "junk.zip"
    junk.write_text("not a zip")
    assert cli_main(["rollout", "--controller", str(junk), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not a Stable-Baselines3 model zip" in err, err
    odd = tmp_path / "odd.zip"
    with zipfile.ZipFile(odd, "w") as z:
        z.writestr("data", json.dumps({"policy_class": {"__module__": "mypkg.policies"}}))
    with pytest.raises(ValueError, match="cannot tell which algorithm saved"):
        model_algo(odd)


def test_a_run_model_without_its_statistics_is_refused(trained_run, tmp_path):
    """A run that normalised observations (config.yml) but whose model lost its VecNormalize
    statistics would act on raw observations: refused, naming the missing file."""
    import shutil

    scene, runs = trained_run
    run = tmp_path / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    (run / "model_vecnormalize.pkl").unlink()
    with pytest.raises(
        ValueError,
        match="has no model_vecnormalize.pkl beside it, but its run normalised observations",
    ):
        load_agent(run / "model.zip", rolling_env.make(str(scene)))


def test_a_scene_that_cannot_be_built_is_one_line_naming_its_keys(tmp_path, capsys):
    """A scene that passes load_scene but needs more spring cells than the model allows
    (resolution 4096 over stroke_roll 0.9 m) crashed evaluate with a traceback: exit 2, one
    line naming the scene keys, nothing written; train says the same."""
    from agents.evaluate import main as evaluate_main
    from agents.train import main as train_main

    huge = _scene_file(tmp_path / "huge.yaml", resolution=4096, stroke_roll=0.9)
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv(huge, runs=tmp_path / "runs", out=tmp_path / "out"))
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    last = err.strip().splitlines()[-1]
    assert "'resolution' = 4096" in last and "'stroke_roll' = 0.9" in last, err
    assert not (tmp_path / "out").exists()
    assert (
        train_main(["--algo", "ppo", "--scene", str(huge), "--run-dir", str(tmp_path / "run")]) == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'resolution' = 4096" in err, err


def test_evaluate_without_agents_refuses_unless_baselines_only(tmp_path, capsys):
    """A mistyped --runs (no such folder) or a scene with no trained agent there replaced the
    committed comparison with a baselines-only table, exit 0: now exit 2 naming --runs (and
    the scene) with nothing written; --baselines-only compares the two baselines alone."""
    from agents.evaluate import main as evaluate_main

    out = tmp_path / "out"
    base = ["--scenes", "heavy_inf_friction", "--episodes", "1", "--out", str(out)]
    with pytest.raises(SystemExit) as e:
        evaluate_main(base + ["--runs", str(tmp_path / "nonexistent")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--runs: no folder" in err and "--baselines-only" in err, err
    (tmp_path / "runs" / "default" / "ppo_seed0").mkdir(parents=True)  # another scene's run
    with pytest.raises(SystemExit) as e:
        evaluate_main(base + ["--runs", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "no trained agent for scene 'heavy_inf_friction'" in err, err
    assert not out.exists() or not any(out.rglob("comparison*")), "a table was written"
    assert evaluate_main(base + ["--baselines-only", "--runs", str(tmp_path / "nonexistent")]) == 0
    with open(out / "comparison.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["controller"] for r in rows] == ["eq32-open-loop", "eq32-feedback"], rows


# ----------------------------------------------------------------- bad inputs
def test_evaluate_bounds_episodes(tmp_path, capsys, monkeypatch):
    """--episodes 1000000000 had no upper bound: the held-out targets were built until the
    process was killed for memory.  Now exit 2 at parse time naming --episodes and its range
    (1 to EPISODES_MAX), before any target is drawn or file written."""
    import agents.evaluate as ev

    def reached(*a, **k):
        raise AssertionError("the evaluation started with an unbounded --episodes")

    monkeypatch.setattr(ev, "held_out_targets", reached)
    for bad in ("1000000000", "100001", "0", "-3", "2.5"):
        with pytest.raises(SystemExit) as e:
            ev.main(
                [
                    "--baselines-only",
                    "--scenes",
                    "default",
                    "--episodes",
                    bad,
                    "--out",
                    str(tmp_path / "out"),
                ]
            )
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]
        assert e.value.code == 2 and "--episodes" in last, f"{bad}: {err}"
        assert bad == "2.5" or "[1, 100000]" in last, f"{bad}: {err}"
    assert not (tmp_path / "out").exists()


def test_evaluate_refuses_duplicate_scenes(tmp_path, capsys):
    """--scenes default default evaluated the scene twice and wrote duplicate rows: refused
    naming --scenes, also where two spellings (name, path of the shipped file) have one key."""
    from agents.evaluate import main as evaluate_main

    shipped = str(rolling_env.env.scenes.SCENE_DIR / "default.yaml")
    for scenes in (["default", "default"], ["default", "heavy_inf_friction", shipped]):
        with pytest.raises(SystemExit) as e:
            evaluate_main(_eval_argv(*scenes, out=tmp_path / "out", extra=["--baselines-only"]))
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert e.value.code == 2 and "--scenes:" in last and "same scene key 'default'" in last, (
            f"{scenes}: {last}"
        )
    assert not (tmp_path / "out").exists()


def test_evaluate_refuses_a_run_named_like_a_baseline(trained_run, tmp_path, capsys):
    """A run folder named eq32-feedback replaced the baseline's row silently."""
    import shutil

    from agents.evaluate import main as evaluate_main

    scene, runs = trained_run
    shutil.copytree(runs / "myscene" / "ppo_seed0", tmp_path / "runs" / "myscene" / "eq32-feedback")
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv(scene, runs=tmp_path / "runs", out=tmp_path / "out"))
    err = capsys.readouterr().err
    assert e.value.code == 2 and "has the name of a baseline" in err, err


def _damage(run: Path, kind: str) -> str:
    """Damage one file of a copied run folder; returns the name of the damaged file."""
    import zipfile

    cfg = run / "config.yml"
    if kind == "yaml":
        cfg.write_text("scene: [\n")
    elif kind == "list":
        cfg.write_text("- 1\n- 2\n")
    elif kind == "env_kwargs":
        cfg.write_text(yaml.safe_dump(dict(yaml.safe_load(cfg.read_text()), env_kwargs=[1, 2])))
    elif kind == "utf8":
        cfg.write_bytes(b"scene: \xff\xfe\n")
    elif kind == "pkl":
        stats = run / "model_vecnormalize.pkl"
        stats.write_bytes(stats.read_bytes()[: len(stats.read_bytes()) // 2])
        return stats.name
    elif kind == "pth":
        good = run / "model.zip"
        bad = run / "bad.zip"
        with zipfile.ZipFile(good) as zi, zipfile.ZipFile(bad, "w") as zo:
            for item in zi.infolist():
                data = zi.read(item.filename)
                zo.writestr(item, data[: len(data) // 2] if item.filename == "policy.pth" else data)
        bad.replace(good)
        return good.name
    elif kind == "meta":
        (run / "meta.json").write_text('{"env_steps": 64, "wall')
        return "meta.json"
    elif kind == "npz":
        ev = run / "evaluations.npz"
        ev.write_bytes(ev.read_bytes()[:100])
        return ev.name
    return cfg.name


@pytest.mark.parametrize(
    "kind", ["yaml", "list", "env_kwargs", "utf8", "pkl", "pth", "meta", "npz"]
)
def test_damaged_run_files_are_one_line_naming_the_file(trained_run, tmp_path, capsys, kind):
    """A config.yml that is invalid YAML, a list, has env_kwargs [1, 2] or is not UTF-8, a
    truncated model_vecnormalize.pkl, a model.zip with a damaged policy.pth (and, for
    evaluate, a damaged meta.json or evaluations.npz) gave raw tracebacks, exit 1: now one
    line naming the file, exit 2, in `rolling-drive rollout` and `agents.evaluate`, with
    nothing written."""
    import shutil

    from agents.evaluate import main as evaluate_main
    from rolling_env.cli.main import main as cli_main

    scene, runs = trained_run
    run = tmp_path / "runs" / "myscene" / "ppo_seed0"
    shutil.copytree(runs / "myscene" / "ppo_seed0", run)
    for f in run.glob("best_model*"):  # model.zip is the file used
        f.unlink()
    name = _damage(run, kind)
    out = tmp_path / "out"
    if kind not in ("meta", "npz"):  # the rollout reads neither
        code = cli_main(
            [
                "rollout",
                "--scene",
                str(scene),
                "--controller",
                str(run / "model.zip"),
                "--out",
                str(out),
            ]
        )
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, f"{kind}: exit {code}: {err}"
        assert err.startswith("rolling-drive rollout: error:") and name in err, f"{kind}: {err}"
    with pytest.raises(SystemExit) as e:
        evaluate_main(_eval_argv(scene, runs=tmp_path / "runs", out=out))
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert e.value.code == 2 and name in last and "Traceback" not in last, f"{kind}: {last}"
    assert not [p for p in out.rglob("*") if p.is_file()], f"{kind}: files written"


def test_scene_runs_skips_hidden_and_overwrite_folders(tmp_path):
    """The run folders of a scene are its visible subfolders: a hidden one (an earlier run
    that ``--overwrite`` could not delete) and ``<run>.overwrite`` (a replacement that failed
    or was stopped) were evaluated as extra controllers."""
    from agents.loading import scene_runs

    base = tmp_path / "runs" / "default"
    for name in ("ppo_seed0", "sac_seed0", ".ppo_seed0.replaced-123", "ppo_seed0.overwrite"):
        (base / name).mkdir(parents=True)
    (base / "notes.txt").write_text("not a run")
    got = [p.name for p in scene_runs("default", tmp_path / "runs")]
    assert got == ["ppo_seed0", "sac_seed0"], got
