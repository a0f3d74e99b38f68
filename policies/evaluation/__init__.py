"""The paper's metrics: episodes flown by a policy on a scenario split (in parallel if asked), their statistics
and aggregates, and the scripted baselines evaluated the same way."""
