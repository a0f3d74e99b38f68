"""``hrlsac export``'s work: a checkpoint's deterministic policy as one self-describing TorchScript (or
torch.export) artifact, checked for parity with the checkpoint."""
