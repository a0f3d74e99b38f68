"""Learning: the gymnasium environment, SAC / HRL-SAC agents, training, evaluation and export."""
