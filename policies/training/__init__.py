"""A training run: the trainer that drives environments and agents, its checkpoints, and sweeps of runs."""
