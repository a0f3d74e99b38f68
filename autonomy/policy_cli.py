"""``hrlsac policy``: inspect exported policy artifacts (``policy info``) with the on-board runtime only."""
from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autonomy.policy import Policy


def main(argv: list[str], prog: str = "hrlsac policy") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip())
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    info = commands.add_parser("info", help="print an artifact's manifest and check the file (loads and runs it)",
                               description="Print an artifact's manifest and check it as the runtime would: "
                                           "archive intact, manifest version and observation layout matching "
                                           "this runtime, both entry points answering.")
    info.add_argument("artifact", help="policy artifact written by hrlsac export")
    info.add_argument("--json", action="store_true", help="print the manifest as JSON")
    args = parser.parse_args(argv)
    from autonomy.policy import PolicyArtifactError, load_policy

    try:
        policy = load_policy(args.artifact)
    except PolicyArtifactError as exc:
        print(f"{prog} {args.command}: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(policy.manifest.to_json())
    else:
        print("\n".join(info_lines(policy)))
    print(f"check: ok ({policy.path}, sha256 {policy.sha256})", file=sys.stderr if args.json else sys.stdout)
    return 0


def info_lines(policy: Policy) -> list[str]:
    """The summary, then the contract in full: entry points, goals, action spec, observation layout."""
    from autonomy.policy_manifest import summary_lines

    manifest = policy.manifest
    lines = summary_lines(manifest) + ["", "entry points:"]
    lines += [f"  {name}: {signature}" for name, signature in manifest.entry_points.items()]
    if manifest.goals:
        lines += ["", f"goals (a decision every K = {manifest.subgoal_interval} steps):"]
        lines += [f"  {g.index} {g.name}: {g.grounding}" for g in manifest.goals]
    lines += ["", "actions:"]
    lines += [f"  {name:18s} {f'[{low:g}, {high:g}]':8s} {unit}" for name, low, high, unit
              in zip(manifest.action.names, manifest.action.low, manifest.action.high, manifest.action.units)]
    lines += ["", f"observation (layout version {manifest.observation.layout_version}):"]
    lines += [f"  {f['name']:16s} offset {f['offset']:3d} size {f['size']:3d}  {f['description']}"
              for f in manifest.observation.fields]
    if isinstance(manifest.evaluation, dict):  # the summary says "not evaluated" otherwise
        lines += ["", "evaluation:"]
        lines += [f"  {split}: {json.dumps(metrics)}" for split, metrics in manifest.evaluation.items()]
    return lines
