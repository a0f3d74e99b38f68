"""Offline tools that compose the on-board runtime (``autonomy``) with the simulated vehicle (``sitl_bridge``):
mission replay in lockstep, replays of many seeds in parallel, the outcome of a flight, and the worker pool that
spreads episodes over processes or Ray. A companion computer needs none of it."""
