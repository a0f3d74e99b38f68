"""The ``hrlsac`` command: a thin dispatcher over the packages' own command modules.

Each subcommand lives in the package that owns it and is imported only when it is run, so that
``hrlsac --help`` stays fast (no torch, no pymavlink import). A command module exposes
``main(argv: list[str], prog: str) -> int``.
"""
from __future__ import annotations

import importlib
import sys

# name -> (module implementing ``main(argv, prog)``, one-line summary for ``hrlsac --help``)
COMMANDS: dict[str, tuple[str, str]] = {
    "sitl": ("sitl_bridge.cli", "run the simulated PX4-like multirotor and wait for MAVLink clients"),
    "demo": ("sitl_bridge.scripted_flight", "fly a short scripted mission in the simulated vehicle and report"),
    "train": ("policies.train_cli", "train HRL-SAC or flat SAC on the search environment (resumable)"),
    "evaluate": ("policies.evaluate_cli", "the paper's metrics of a trained run on a scenario split"),
    "dataset": ("missions.dataset_cli", "make the synthetic SAR dataset or inspect a YOLO dataset"),
    "compare": ("policies.compare_cli", "compare trained runs and the scripted baselines: markdown report and figures"),
    "export": ("policies.export_cli", "write a checkpoint's policy as one self-describing artifact (policy.pt)"),
    "policy": ("autonomy.policy_cli", "inspect an exported policy artifact (policy info) with the on-board runtime"),
    "mission": ("autonomy.mission_cli", "fly a search mission with a policy: replay in the simulated vehicle, or run"),
}

USAGE = "usage: hrlsac [-h] [--version] COMMAND [ARGS...]"


def _help() -> str:
    width = max(len(name) for name in COMMANDS)
    lines = [USAGE, "", "HRL-SAC search-and-rescue autonomy stack.", "", "commands:"]
    lines += [f"  {name:<{width}}  {summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", "Run 'hrlsac COMMAND --help' for the options of one command."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hrlsac`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_help())
        return 0 if argv else 2
    if argv[0] == "--version":
        from importlib.metadata import PackageNotFoundError, version

        try:
            print(f"hrlsac {version('hrlsac')}")
        except PackageNotFoundError:
            print("hrlsac (not installed)")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"hrlsac: error: unknown command '{name}' (choose from {', '.join(COMMANDS)})", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    try:
        return int(module.main(rest, prog=f"hrlsac {name}") or 0)
    except KeyboardInterrupt:
        print(f"hrlsac {name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
