"""Controllers for RollingDrive-v0: Eq. 32 baselines and Stable-Baselines3 training/evaluation."""
