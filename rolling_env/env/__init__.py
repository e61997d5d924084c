"""The environment: the single env (``drive_env``), its compiled step (``_envkernel``), the
batched core and vector env (``vector``, ``threads``), the Stable-Baselines3 adapter
(``sb3_vec``), scenes (``scenes``), the action mapping (``actions``), rendering (``render``),
the Eq. 32 controllers (``baselines``) and the rollout of a controller (``rollout``)."""
