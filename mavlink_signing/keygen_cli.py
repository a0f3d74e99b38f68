"""``hrlsac keygen FILE``: write a fresh MAVLink 2 signing key (64 hex characters, mode 0600, atomically).

Give the same file to ``hrlsac sitl --signing-key FILE`` and ``hrlsac mission run|replay --signing-key FILE``
(or to a real autopilot with SETUP_SIGNING) so that both ends sign and check every message.
"""
from __future__ import annotations

import argparse
import sys

from mavlink_signing import KeyFileError, generate_key, write_key_file


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(": ", 1)[1].split("\n\n")[0])
    parser.add_argument("file", metavar="FILE", help="where to write the key (refused if it exists)")
    parser.add_argument("--force", action="store_true", help="replace an existing key file")
    return parser


def main(argv: list[str], prog: str = "hrlsac keygen") -> int:
    args = build_parser(prog).parse_args(argv)
    try:
        write_key_file(args.file, generate_key(), force=args.force)
    except KeyFileError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote a new 32-byte signing key to {args.file} (mode 0600); keep it secret")
    return 0
