"""``hrlsac export``: write a training checkpoint's deterministic policy, or a Stable-Baselines3 SAC model's
(--from-sb3 MODEL.zip), as one self-describing artifact."""
from __future__ import annotations

import argparse
import json
import sys

from hrlsac_cli.help_format import HelpFormatter


def main(argv: list[str], prog: str = "hrlsac export") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     epilog="The artifact format is described in docs/export.md.",
                                     formatter_class=HelpFormatter)
    parser.add_argument("checkpoint", nargs="?",
                        help="run folder (its checkpoint.pt) or checkpoint file written by hrlsac train")
    parser.add_argument("--from-sb3", metavar="MODEL.zip", default=None,
                        help="export the Stable-Baselines3 SAC model that model.save wrote (trained on SarSearch-v1) "
                             "instead of a checkpoint; always checked against SB3's own predict before writing")
    parser.add_argument("--env-kwargs", metavar="JSON", default=None,
                        help="with --from-sb3: the keyword arguments of the model's gymnasium.make('SarSearch-v1', "
                             "...) as a JSON object, e.g. '{\"action_frame\": \"arrive\"}' (default: none)")
    parser.add_argument("-o", "--out", required=True, help="artifact to write, e.g. policy.pt")
    parser.add_argument("--format", choices=["torchscript", "torch-export"], default="torchscript")
    parser.add_argument("--precision", choices=["float32", "int8"], default="float32",
                        help="the low-level actor's arithmetic: float32 (as trained) or int8 weights with bfloat16 "
                             "activations (faster at batch 1; actions within 0.05, goals exact: docs/export.md)")
    parser.add_argument("--check", action="store_true",
                        help="before writing, check on 10,000 recorded observations that the artifact acts like "
                             "the checkpoint (actions within the precision's tolerance, same goals)")
    args = parser.parse_args(argv)
    if (args.checkpoint is None) == (args.from_sb3 is None):
        parser.error("give exactly one of CHECKPOINT and --from-sb3 MODEL.zip")
    if args.from_sb3 is None and args.env_kwargs is not None:
        parser.error("--env-kwargs goes with --from-sb3 (a checkpoint records its environment itself)")
    if args.from_sb3 is not None and args.precision != "float32":
        parser.error("--precision int8 is for hrlsac checkpoints; a Stable-Baselines3 model exports in float32")
    env_kwargs = None
    if args.env_kwargs is not None:
        try:
            env_kwargs = json.loads(args.env_kwargs)
        except json.JSONDecodeError as exc:
            parser.error(f"--env-kwargs is not valid JSON ({exc})")
        if not isinstance(env_kwargs, dict):
            parser.error("--env-kwargs must be a JSON object of gymnasium.make keyword arguments")
    from autonomy.policy_manifest import summary_lines
    from policies.export.artifact import ParityError, export_policy

    try:
        if args.from_sb3 is not None:
            from policies.export.sb3 import export_sb3_policy

            result = export_sb3_policy(args.from_sb3, args.out, args.format, env_kwargs)
        else:
            result = export_policy(args.checkpoint, args.out, args.format, check=args.check,
                                   precision=args.precision)
    except (FileNotFoundError, ImportError, ValueError) as exc:  # ValueError includes PolicyArtifactError
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except ParityError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {result.path} ({result.size_bytes / 1e6:.2f} MB)")
    for line in summary_lines(result.manifest):
        print(line)
    for note in result.notes:
        print(f"  note: {note}")
    if result.parity is not None:
        source = "Stable-Baselines3's predict" if args.from_sb3 is not None else "the checkpoint"
        print(f"  parity with {source}: {result.parity.summary()}: ok")
    return 0
