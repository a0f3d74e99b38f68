"""Learning: the gymnasium environment, SAC / HRL-SAC agents, training, evaluation and export.

Importing this package registers ``SarSearch-v0`` with gymnasium::

    import gymnasium, policies
    env = gymnasium.make("SarSearch-v0", split="train")
    envs = gymnasium.make_vec("SarSearch-v0", num_envs=64, vectorization_mode="vector_entry_point")
"""
import gymnasium

if "SarSearch-v0" not in gymnasium.registry:
    gymnasium.register(id="SarSearch-v0", entry_point="policies.env:SarSearchEnv",
                       vector_entry_point="policies.vector_env:SarSearchVectorEnv")
