"""Learning: the gymnasium environment, SAC / HRL-SAC agents, training, evaluation and export.

Importing this package registers ``SarSearch-v0`` (the paper's task) and ``SarSearch-v1`` (docs/environment.md)
with gymnasium::

    import gymnasium, policies
    env = gymnasium.make("SarSearch-v1", split="train")
    envs = gymnasium.make_vec("SarSearch-v1", num_envs=64, vectorization_mode="vector_entry_point")
"""
import gymnasium

for _task in ("SarSearch-v0", "SarSearch-v1"):
    if _task not in gymnasium.registry:
        gymnasium.register(id=_task, entry_point="policies.env.gym_env:SarSearchEnv",
                           vector_entry_point="policies.env.vector:SarSearchVectorEnv", kwargs={"task": _task})
