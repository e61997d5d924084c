"""Where the shipped configuration files are: ``configs/`` (scenes, hyper-parameters, sweeps).

In a checkout (and an editable install) that is the repository's ``configs/`` folder; a built
wheel carries the same files as ``rolling_env/_configs`` (``pyproject.toml`` maps the one to
the other), so that an installed package finds its scenes from any working folder.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGED = Path(__file__).resolve().parent / "_configs"
_CHECKOUT = Path(__file__).resolve().parent.parent / "configs"

#: The folder holding ``scenes/``, ``hyperparams/`` and ``sweeps/``.
CONFIG_DIR = _PACKAGED if _PACKAGED.is_dir() else _CHECKOUT
SCENE_DIR = CONFIG_DIR / "scenes"
HYPERPARAM_DIR = CONFIG_DIR / "hyperparams"
SWEEP_DIR = CONFIG_DIR / "sweeps"
