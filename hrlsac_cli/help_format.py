"""The help formatter of every ``hrlsac`` subcommand (beside the dispatcher; it imports nothing of the project, so
every package's command module may import it)."""
from __future__ import annotations

import argparse


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's formatter that appends "(default: X)" to each option's help, except where that says nothing or
    says it twice: an option off by default (None, or an empty list for a repeatable one), an on/off flag (False),
    or help text that names its default itself ("default: the mission's name")."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        empty = action.default is None or action.default == []
        if empty or action.nargs == 0 or "default:" in text or "(default" in text:
            return action.help
        return super()._get_help_string(action)
