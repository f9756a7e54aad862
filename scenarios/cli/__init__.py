"""The ``grindtwin`` command: a parser whose subcommands live in :mod:`scenarios.cli.commands`.

Exit codes: 0 success, 2 bad input (one clear line, no traceback), 1 a run that failed.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from .commands import COMMANDS


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad argument in one line and exits 2."""

    def error(self, message):
        sys.stderr.write(f"grindtwin: error: {message}\n")
        raise SystemExit(2)


class _Version(argparse.Action):
    """``--version``: the installed distribution's version (read when asked, so that every other
    command starts without importlib.metadata) and Python's."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="print grindtwin's version and exit"):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        import platform
        from importlib.metadata import PackageNotFoundError, version

        try:
            mine = version("grindtwin")
        except PackageNotFoundError:
            mine = "(not installed: run from a checkout)"
        print(f"grindtwin {mine} (Python {platform.python_version()})")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="grindtwin", description="Digital twin of ore grinding and its model predictive controller.")
    p.add_argument("--version", action=_Version)
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add, _ in COMMANDS.values():
        add(sub)
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as the command's other warnings read: one line on stderr, no source line."""
    sys.stderr.write(f"grindtwin: warning: {message} ({category.__name__})\n")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    with warnings.catch_warnings():  # the caller's way of showing warnings is put back after
        warnings.showwarning = _show_warning
        return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
