"""``hrlsac export``: write a training checkpoint's deterministic policy as one self-describing artifact."""
from __future__ import annotations

import argparse
import sys

from hrlsac_cli.help_format import HelpFormatter


def main(argv: list[str], prog: str = "hrlsac export") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     epilog="The artifact format is described in docs/export.md.",
                                     formatter_class=HelpFormatter)
    parser.add_argument("checkpoint", help="run folder (its checkpoint.pt) or checkpoint file written by hrlsac train")
    parser.add_argument("-o", "--out", required=True, help="artifact to write, e.g. policy.pt")
    parser.add_argument("--format", choices=["torchscript", "torch-export"], default="torchscript")
    parser.add_argument("--precision", choices=["float32", "int8"], default="float32",
                        help="the low-level actor's arithmetic: float32 (as trained) or int8 weights with bfloat16 "
                             "activations (faster at batch 1; actions within 0.05, goals exact: docs/export.md)")
    parser.add_argument("--check", action="store_true",
                        help="before writing, check on 10,000 recorded observations that the artifact acts like "
                             "the checkpoint (actions within the precision's tolerance, same goals)")
    args = parser.parse_args(argv)
    from autonomy.policy_manifest import summary_lines
    from policies.export.artifact import ParityError, export_policy

    try:
        result = export_policy(args.checkpoint, args.out, args.format, check=args.check, precision=args.precision)
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
        print(f"  parity with the checkpoint: {result.parity.summary()}: ok")
    return 0
