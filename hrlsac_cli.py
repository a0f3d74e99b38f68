"""The ``hrlsac`` command: a thin dispatcher over the packages' own command modules.

Each subcommand lives in the package that owns it and is imported only when it is run, so that
``hrlsac --help`` stays fast (no torch, no pymavlink import). A command module exposes
``main(argv: list[str], prog: str) -> int``.
"""
from __future__ import annotations

import importlib
import os
import sys

# name -> (module implementing ``main(argv, prog)``, one-line summary for ``hrlsac --help``)
COMMANDS: dict[str, tuple[str, str]] = {
    "sitl": ("sitl_bridge.cli", "run the simulated multirotor (PX4 or ArduPilot) and wait for MAVLink clients"),
    "demo": ("sitl_bridge.scripted_flight", "fly a short scripted mission in the simulated vehicle and report"),
    "train": ("policies.train_cli", "train HRL-SAC or flat SAC on the search environment (resumable)"),
    "sweep": ("policies.sweep_cli", "train a grid of runs (algorithm x preset x seed x hyper-parameters) on Ray"),
    "evaluate": ("policies.evaluate_cli", "the paper's metrics of a trained run on a scenario split"),
    "dataset": ("missions.dataset_cli", "make the synthetic SAR dataset or inspect a YOLO dataset"),
    "compare": ("policies.compare_cli", "compare trained runs and the scripted baselines: markdown report and figures"),
    "export": ("policies.export_cli", "write a checkpoint's policy as one self-describing artifact (policy.pt)"),
    "policy": ("autonomy.policy_cli", "inspect an exported policy artifact (policy info) with the on-board runtime"),
    "mission": ("autonomy.mission_cli", "fly a search mission with a policy: replay in the simulated vehicle, or run"),
    "keygen": ("missions.keygen_cli", "write a fresh MAVLink 2 signing key file (for --signing-key)"),
}

USAGE = "usage: hrlsac [-h] [--version] COMMAND [ARGS...]"
TRACEBACK_ENV = "HRLSAC_TRACEBACK"
"""Set to 1 to see the Python traceback of an unexpected error instead of its one-line summary."""


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
    try:
        module = importlib.import_module(COMMANDS[name][0])
        return int(module.main(rest, prog=f"hrlsac {name}") or 0)
    except KeyboardInterrupt:
        print(f"hrlsac {name}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of our output went away (`hrlsac ... | head`): stop quietly, like cat
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes
        return 141
    except Exception as exc:  # what a command did not turn into its own error: one line, the traceback on request
        if os.environ.get(TRACEBACK_ENV, "") not in ("", "0"):
            raise
        lines = str(exc).strip().splitlines()
        detail = f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__
        if isinstance(exc, OSError):  # a file or device problem (disk full, permission denied): the user's to fix
            print(f"hrlsac {name}: error: {detail}", file=sys.stderr)
        else:
            print(f"hrlsac {name}: error: unexpected {detail} (a bug, please report it; rerun with {TRACEBACK_ENV}=1 "
                  "for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
