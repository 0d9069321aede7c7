"""Command-line interface: ``shipid <command> ...`` (also ``python -m shipid``).

The CLI is a thin layer over the library.  Each command lives in a module that
exposes ``register(subparsers)``; the module list is :data:`COMMAND_MODULES`.
A handler returns an exit code.  Any ``ValueError`` (bad input, bad option)
is printed as one line on stderr and exits with code 2 -- never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["main", "COMMAND_MODULES"]

#: Modules that add sub-commands (each has ``register(subparsers)``).
COMMAND_MODULES: list[str] = [
    "shipid.commands.core",
    "shipid.commands.identify",
    "shipid.commands.logs",
    "shipid.commands.manoeuvre",
    "shipid.commands.routing",
    "shipid.commands.glider",
    "shipid.commands.validate",
    "shipid.commands.control",
    "shipid.commands.uncertainty",
]


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors -> exit 2, one line
        self.print_usage(sys.stderr)
        raise _UsageError(f"{self.prog}: error: {message}")


class _UsageError(Exception):
    pass


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = _Parser(prog="shipid", description="Identify, validate and use ship manoeuvring models.")
    parser.add_argument("--version", action="version", version=f"shipid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for mod in COMMAND_MODULES:
        importlib.import_module(mod).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 numerical failure, 2 bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args.handler(args) or 0)
    except (ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        msg = " ".join(str(exc).split())
        print(f"shipid {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("shipid: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
