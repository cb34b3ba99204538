"""Training algorithms over `NavEnv`: PPO (TorchRL collectors + ClipPPOLoss), behaviour cloning from
expert episodes, atomic resumable checkpoints, and a tiny logger protocol."""
