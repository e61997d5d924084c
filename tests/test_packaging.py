"""The package's shape: what imports what, and a built wheel that works outside the checkout.

* ``rolling_env`` (the library) never imports ``agents`` and loads no file of ``tests/``;
  ``agents`` builds on ``rolling_env``.
* Neither package has an import cycle among its modules (imports inside functions count:
  a lazy import still ties the two modules together).
* A wheel built from the sources, installed outside the checkout, finds its scenes and
  hyper-parameters from any working folder (they ship inside it as ``rolling_env/_configs``).
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def _modules(package: str) -> dict[str, Path]:
    out = {}
    for p in sorted((REPO / package).rglob("*.py")):
        name = ".".join(p.relative_to(REPO).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = p
    return out


def _imports(name: str, path: Path, known) -> set[str]:
    """Absolute names of the modules ``path`` imports anywhere in it (``from x import y``
    counts as importing ``x.y`` where that is a module of ``known``, else ``x``)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
                mod = ".".join(parts + ([node.module] if node.module else []))
            else:
                mod = node.module
            subs = [f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in known]
            out.update(subs)
            if len(subs) < len(node.names):
                out.add(mod)
    return out


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (depth-first search), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in sorted(graph[v]):
            if state.get(w) == 1:
                return stack[stack.index(w) :] + [w]
            if w not in state:
                found = visit(w)
                if found:
                    return found
        stack.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state:
            found = visit(v)
            if found:
                return found
    return None


def test_the_library_imports_no_agent_code_and_no_test_file():
    mods = _modules("rolling_env")
    for name, path in mods.items():
        imported = _imports(name, path, mods)
        bad = sorted(m for m in imported if m.split(".")[0] in ("agents", "tests"))
        assert not bad, f"{name} imports {bad}: the library must not depend on them"
        text = path.read_text(encoding="utf-8")
        assert "spec_from_file_location" not in text, f"{name} loads a module by path"


LAYERS = ("physics", "env", "studies", "cli")  # each may import those before it
TOP_UTILITIES = ("rolling_env.io", "rolling_env.validation", "rolling_env.paths")


def _layer(name: str) -> int | None:
    parts = name.split(".")
    return LAYERS.index(parts[1]) if len(parts) > 1 and parts[1] in LAYERS else None


def test_each_layer_of_the_library_imports_only_the_layers_below_it():
    """physics < env < studies < cli: the physics knows no env, the env no study, no study
    the command line; the top-level utilities serve every layer, and ``rolling_env`` itself
    (``make``, which builds an env) only the studies and the CLI."""
    mods = _modules("rolling_env")
    for name, path in mods.items():
        own = _layer(name)
        if own is None:
            continue
        for dep in _imports(name, path, mods):
            if not dep.startswith("rolling_env") or dep in TOP_UTILITIES:
                continue
            if dep == "rolling_env":
                assert own >= LAYERS.index("studies"), f"{name} imports rolling_env (make)"
                continue
            layer = _layer(dep)
            assert layer is not None and layer <= own, (
                f"{name} ({LAYERS[own]}) imports {dep}: allowed are "
                f"{', '.join(LAYERS[: own + 1])} and {', '.join(TOP_UTILITIES)}"
            )


@pytest.mark.parametrize("package", ["rolling_env", "agents"])
def test_no_import_cycle_among_a_packages_modules(package):
    mods = _modules(package)
    graph = {m: {d for d in _imports(m, p, mods) if d in mods and d != m} for m, p in mods.items()}
    # importing a submodule runs its package's __init__: that edge is not a dependency
    graph = {m: {d for d in ds if d != package} for m, ds in graph.items()}
    cycle = _cycle(graph)
    assert cycle is None, f"import cycle: {' -> '.join(cycle)}"


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def _sources(dest: Path) -> None:
    """Copy the tracked sources (all files but caches and venvs without git) into ``dest``."""
    try:
        files = subprocess.run(
            ["git", "-C", str(REPO), "ls-files", "-co", "--exclude-standard"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        files = [str(p.relative_to(REPO)) for p in REPO.rglob("*") if p.is_file()]
        files = [f for f in files if not f.startswith((".venv", ".ci-venv", ".git/", "runs/"))]
    keep = ("rolling_env/", "agents/", "configs/", "pyproject.toml", "README.md", "LICENSE")
    for f in files:
        if f.startswith(keep) and (REPO / f).is_file() and "__pycache__" not in f:
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / f, dest / f)


def test_a_built_wheel_runs_its_scenes_from_any_folder(tmp_path):
    """Build the wheel from a copy of the sources, install it (without dependencies: those of
    this environment serve) into a folder of its own, and use it from an empty folder."""
    src, dist, site, work = (tmp_path / n for n in ("src", "dist", "site", "work"))
    for d in (src, dist, work):
        d.mkdir()
    _sources(src)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    build = subprocess.run(
        pip + ["wheel", "--no-deps", "--no-build-isolation", str(src), "-w", str(dist)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert build.returncode == 0, f"the wheel did not build:\n{build.stderr[-3000:]}"
    (wheel,) = dist.glob("rolling_drive-*.whl")
    inst = subprocess.run(
        pip + ["install", "--no-deps", "--target", str(site), str(wheel)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert inst.returncode == 0, f"the wheel did not install:\n{inst.stderr[-3000:]}"
    assert not (site / "configs").exists(), "the wheel installs a top-level 'configs' folder"
    code = "\n".join(
        [
            "import json, sys, numpy as np, gymnasium as gym",
            "import rolling_env, agents",
            "from rolling_env.env.scenes import list_scenes",
            "from rolling_env.paths import CONFIG_DIR",
            "from agents.common import load_hyperparams",
            "from importlib.metadata import entry_points",
            "out = {'rolling_env': rolling_env.__file__, 'agents': agents.__file__,",
            "       'configs': str(CONFIG_DIR), 'scenes': list_scenes(), 'steps': {}}",
            "for s in out['scenes']:",
            "    env = gym.make('RollingDrive-v0', scene=s)",
            "    env.reset(seed=0)",
            "    obs, r, term, trunc, info = env.step(np.zeros(3, np.float32))",
            "    out['steps'][s] = bool(np.isfinite(obs).all() and np.isfinite(r))",
            "out['ppo'] = load_hyperparams('ppo', 'default')['n_timesteps']",
            "out['loaders'] = sorted(e.name for e in entry_points(",
            "    group='rolling_drive.model_loaders'))",
            "print(json.dumps(out))",
        ]
    )
    env = dict(os.environ, PYTHONPATH=str(site), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=work, capture_output=True, text=True, env=env, timeout=600
    )
    assert run.returncode == 0, f"the installed wheel failed:\n{run.stderr[-3000:]}"
    import json

    out = json.loads(run.stdout.strip().split("\n")[-1])
    for key in ("rolling_env", "agents", "configs"):
        assert Path(out[key]).resolve().is_relative_to(site.resolve()), (
            f"{key} came from {out[key]}, not from the installed wheel in {site}"
        )
    shipped = sorted(p.stem for p in (REPO / "configs" / "scenes").glob("*.yaml"))
    assert out["scenes"] == shipped, f"the wheel ships scenes {out['scenes']}, not {shipped}"
    assert all(out["steps"].values()), f"a scene did not step from the wheel: {out['steps']}"
    assert out["ppo"] > 0, "the wheel's PPO hyper-parameters for default did not load"
    assert "sb3" in out["loaders"], "the wheel registers no model loader for rollouts"


def test_a_model_without_an_installed_loader_is_one_line(monkeypatch, tmp_path):
    """Without a package registering a model loader, a model .zip is refused by name."""
    import importlib.metadata

    import rolling_env
    from rolling_env.env import rollout

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: [])
    model = tmp_path / "model.zip"
    model.write_bytes(b"")
    env = rolling_env.make("default")
    with pytest.raises(
        ValueError, match=r"model\.zip.*no model loader is installed.*model_loaders"
    ):
        rollout.make_controller(str(model), env)
    env.close()
