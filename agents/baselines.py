"""The Eq. 32 baseline controllers (``Eq32Design``, ``Eq32OpenLoop``, ``Eq32Feedback``).

They are physics, not learning: they live in ``rolling_env.env.baselines``, where the library's
own studies (``rolling-drive accuracy``, rollouts) drive them, and are re-exported here for
the agents' scripts and for code that imports them from ``agents``.
"""

from rolling_env.env.baselines import Eq32Design, Eq32Feedback, Eq32OpenLoop, scene_of

__all__ = ["Eq32Design", "Eq32Feedback", "Eq32OpenLoop", "scene_of"]
