"""The search environment: its batched core, the SarSearch-v1 task, the gymnasium and vector wrappers, the
low-level reward shaping, and the scripted searchers that fly it."""
