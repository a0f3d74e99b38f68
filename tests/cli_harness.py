"""Run ``hrlsac`` in-process and check that bad input ended as a clean error (the tests/test_bad_*.py files).

In-process (``hrlsac_cli.main(argv)``) keeps these tests fast: no interpreter start, no torch import per case.
argparse leaves with ``SystemExit``; everything else a command does must come back as an exit code.
"""
from __future__ import annotations

import contextlib
import io
import sys
from dataclasses import dataclass

import hrlsac_cli

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]
"""The command as a subprocess (for the few end-to-end checks)."""


@dataclass
class CliResult:
    """What one ``hrlsac`` call printed and returned."""

    code: int
    out: str
    err: str

    @property
    def error_line(self) -> str:
        """The last line of stderr: argparse prints its usage first, then the one error line."""
        lines = self.err.strip().splitlines()
        return lines[-1] if lines else ""


def run_cli(*argv: str) -> CliResult:
    """``hrlsac ARGV`` in this process, its output captured."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = hrlsac_cli.main(list(argv))
        except SystemExit as exc:  # argparse: --help (0) and usage errors (2)
            code = exc.code if isinstance(exc.code, int) else 1
    return CliResult(code, out.getvalue(), err.getvalue())


def assert_clean_error(result: CliResult, *mentions: str, code: int = 2) -> None:
    """Exit ``code``, no traceback anywhere, and an ``error:`` line on stderr that mentions each of ``mentions``."""
    assert result.code == code, (result.code, result.err)
    assert "Traceback" not in result.err + result.out
    line = result.error_line
    assert line.startswith("hrlsac") and ": error: " in line, result.err
    for mention in mentions:
        assert mention in line, (mention, line)
    # Only argparse's usage lines may come before the error line: the message itself is one line.
    assert all(text.startswith(("usage:", " ")) for text in result.err.strip().splitlines()[:-1]), result.err
