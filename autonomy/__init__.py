"""On-board runtime: observation builder, pose estimator, policy runtime, setpoint streaming, mission runner."""
