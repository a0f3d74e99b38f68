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
    "train": ("policies.cli.train", "train HRL-SAC or flat SAC on the search environment (resumable)"),
    "sweep": ("policies.cli.sweep", "train a grid of runs (algorithm x preset x seed x hyper-parameters) on Ray"),
    "evaluate": ("policies.cli.evaluate", "the paper's metrics of a trained run on a scenario split"),
    "dataset": ("missions.dataset_cli", "make the synthetic SAR dataset or inspect a YOLO dataset"),
    "compare": ("policies.cli.compare", "compare trained runs and the scripted baselines: markdown report and figures"),
    "export": ("policies.cli.export", "write a checkpoint's (or a Stable-Baselines3 SAC's) policy as one "
                                       "self-describing artifact (policy.pt)"),
    "policy": ("autonomy.policy_cli", "inspect an exported policy artifact (policy info) with the on-board runtime"),
    "mission": ("", "fly a search mission with a policy: replay in the simulated vehicle, or run"),
    "keygen": ("mavlink_signing.keygen_cli", "write a fresh MAVLink 2 signing key file (for --signing-key)"),
}

# Commands whose subcommands live in different packages: name -> {subcommand: (module, summary)}. The replay
# belongs with the simulator (``simulation``), the real flight with the on-board runtime (``autonomy``), which
# must not import the simulator.
GROUPS: dict[str, dict[str, tuple[str, str]]] = {
    "mission": {
        "replay": ("simulation.replay_cli", "fly the mission in the simulated vehicle, in lockstep (deterministic)"),
        "run": ("autonomy.mission_cli", "fly the mission on a MAVLink vehicle in real time"),
    },
}

USAGE = "usage: hrlsac [-h] [--version] COMMAND [ARGS...]"
TRAIN_EXTRA_MODULES = {"gymnasium": "gymnasium", "cv2": "opencv-python-headless", "matplotlib": "matplotlib",
                       "tensorboard": "tensorboard", "tqdm": "tqdm", "scipy": "scipy"}
"""Modules of the "train" extra, which an on-board install (``pip install hrlsac``) leaves out."""
TRACEBACK_ENV = "HRLSAC_TRACEBACK"
"""Set to 1 to see the Python traceback of an unexpected error instead of its one-line summary."""


def _help() -> str:
    width = max(len(name) for name in COMMANDS)
    lines = [USAGE, "", "HRL-SAC search-and-rescue autonomy stack.", "", "commands:"]
    lines += [f"  {name:<{width}}  {summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", "Run 'hrlsac COMMAND --help' for the options of one command."]
    return "\n".join(lines)


def _choose_subcommand(name: str, rest: list[str]) -> int | None:
    """None if ``rest`` starts with one of the group's subcommands; otherwise print its help or an argparse-style
    error and return the exit code."""
    subcommands = GROUPS[name]
    if rest and rest[0] in subcommands:
        return None
    usage = f"usage: hrlsac {name} [-h] COMMAND ..."
    if rest and rest[0] in ("-h", "--help"):
        width = max(len(sub) for sub in subcommands)
        print("\n".join([usage, "", COMMANDS[name][1] + ".", "", "commands:"]
                        + [f"  {sub:<{width}}  {summary}" for sub, (_, summary) in subcommands.items()]
                        + ["", f"Run 'hrlsac {name} COMMAND --help' for the options of one command."]))
        return 0
    problem = (f"argument COMMAND: invalid choice: '{rest[0]}' (choose from {', '.join(subcommands)})" if rest
               else "the following arguments are required: COMMAND")
    print(f"{usage}\nhrlsac {name}: error: {problem}", file=sys.stderr)
    return 2


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
    prog, module_name = f"hrlsac {name}", COMMANDS[name][0]
    if name in GROUPS:
        chosen = _choose_subcommand(name, rest)
        if isinstance(chosen, int):
            return chosen
        module_name, rest, prog = GROUPS[name][rest[0]][0], rest[1:], f"{prog} {rest[0]}"
    try:
        module = importlib.import_module(module_name)
        return int(module.main(rest, prog=prog) or 0)
    except KeyboardInterrupt:
        print(f"hrlsac {name}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of our output went away (`hrlsac ... | head`): stop quietly, like cat
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes
        return 141
    except Exception as exc:  # what a command did not turn into its own error: one line, the traceback on request
        if isinstance(exc, ModuleNotFoundError) and exc.name in TRAIN_EXTRA_MODULES:
            print(f"{prog}: error: this command needs {TRAIN_EXTRA_MODULES[exc.name]}, which an on-board install "
                  "leaves out: pip install 'hrlsac[train]'", file=sys.stderr)
            return 2
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
