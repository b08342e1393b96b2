"""The help text of every command (``biped-sim ...``, ``biped-sim replay``): one formatter.

argparse's ArgumentDefaultsHelpFormatter appends "(default: X)" to every option, also to those whose
help already says its default in words ("(default: every core) (default: None)"), and its text
filling reflows an epilog of examples into one paragraph. This formatter adds the default only where
the help does not mention one and there is a value to show, and fills each line of a description or
epilog on its own: a paragraph is wrapped, an indented line (an example) is kept as written.
"""
from __future__ import annotations

import argparse
import textwrap


class HelpFormatter(argparse.HelpFormatter):
    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if ("default" in text.lower() or default is None or default is False or default == argparse.SUPPRESS
                or action.option_strings == [] and action.nargs not in ("?", "*")):
            return text
        return text + " (default: %(default)s)"

    def _fill_text(self, text, width, indent):
        lines = []
        for line in text.splitlines():
            if not line.strip() or line[:1].isspace():
                lines.append(indent + line)
            else:
                lines.extend(textwrap.wrap(line, width, initial_indent=indent, subsequent_indent=indent))
        return "\n".join(lines)
