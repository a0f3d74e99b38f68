"""The learners: networks, continuous SAC, discrete SAC, the (prioritised, n-step) replay and the observation
normaliser. Nothing here knows the environment."""
