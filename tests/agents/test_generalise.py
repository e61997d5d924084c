"""Controllers on held-out variants of their scenes (agents.generalise)."""

from __future__ import annotations

import csv
import math

import pytest

import rolling_env
from agents.generalise import _nominal_controllers, main, variants
from agents.residual import ResidualAgent
from tests.train_argv import tiny_ppo_argv


@pytest.mark.parametrize(
    "scene,keys",
    [
        ("default", ["mu x0.5", "mu x2", "runner_mass x0.5", "runner_mass x2"]),
        ("heavy_inf_friction", ["runner_mass x0.5", "runner_mass x2"]),  # mu = inf: no mu variant
        (
            "loaded",
            ["mu x0.5", "mu x2", "runner_mass x0.5", "runner_mass x2", "F_ext x0.5", "F_ext x1.5"],
        ),
    ],
)
def test_variants_change_one_physics_key_by_its_factor(scene, keys):
    nominal = rolling_env.env.scenes.load_scene(scene)
    got = variants(scene)
    assert [label for label, _ in got] == keys
    for label, overrides in got:
        ((key, value),) = overrides.items()
        factor = float(label.split("x")[-1])
        assert math.isclose(value, getattr(nominal, key) * factor, rel_tol=1e-12), label


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory):
    import yaml

    from agents.train import main as train_main

    base = tmp_path_factory.mktemp("gen")
    run = base / "runs" / "loaded" / "ppo-residual_seed0"
    conf = base / "hp.yml"  # trained with the terminal reward term, as the shipped entries
    conf.write_text(
        yaml.safe_dump(
            {
                "loaded": {
                    "env_kwargs": {"scene": "loaded", "w_final": 5.0},
                    "n_steps": 64,
                    "batch_size": 64,
                    "normalize": "{'norm_obs': True, 'norm_reward': True}",
                }
            }
        )
    )
    assert (
        train_main(
            [
                *tiny_ppo_argv(timesteps=128, n_envs=2),
                *("--scene", "loaded", "--conf", str(conf), "--residual", "eq32-feedback"),
                *("--run-dir", str(run)),
            ]
        )
        == 0
    )
    return base / "runs"


def test_every_controller_keeps_its_nominal_design(residual_run):
    """The baselines and a residual agent's baseline are designed on the nominal scene, not
    on the variant they run on."""
    nominal = rolling_env.env.scenes.load_scene("loaded")
    ctrls = _nominal_controllers("loaded", residual_run)
    assert set(ctrls) == {"eq32-open-loop", "eq32-feedback", "ppo-residual_seed0"}
    agent = ctrls["ppo-residual_seed0"]
    assert isinstance(agent, ResidualAgent)
    for c in (ctrls["eq32-feedback"], agent.controller):
        assert c.scene == nominal


def test_generalise_writes_every_variant_and_controller(residual_run, tmp_path):
    out = tmp_path / "out"
    assert (
        main(
            [
                "--runs",
                str(residual_run),
                "--scenes",
                "loaded",
                "--episodes",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    with open(out / "generalisation.csv") as f:
        rows = list(csv.DictReader(f))
    labels = [label for label, _ in variants("loaded")]
    got = {(r["variant"], r["controller"]) for r in rows}
    want = {
        (v, c) for v in labels for c in ("eq32-open-loop", "eq32-feedback", "ppo-residual_seed0")
    }
    assert got == want and len(rows) == 2 * len(want)
    assert all(float(r["final_abs_error_tol"]) >= 0 for r in rows)
    md = (out / "generalisation.md").read_text()
    for v in labels:
        assert f"| loaded {v} | ppo-residual [1] | 1 |" in md, md
    assert "* [1] trained on other numerics or reward weights: w_final 5 (now 0)" in md, md
    # the variants differ: the feedback baseline's final errors are not all the same
    fb = {
        r["variant"]: r["final_abs_error_tol"]
        for r in rows
        if r["controller"] == "eq32-feedback" and r["episode"] == "0"
    }
    assert len(set(fb.values())) > 1, fb


def test_generalise_refuses_a_missing_runs_folder(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--runs", str(tmp_path / "nope"), "--out", str(tmp_path / "out")])
    assert e.value.code == 2 and "--runs" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
