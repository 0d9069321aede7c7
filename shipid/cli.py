"""Command-line interface: ``shipid <command> ...`` (also ``python -m shipid``).

The CLI is a thin layer over the library.  Each command lives in a module that
exposes ``register(subparsers)``; the module list is :data:`COMMAND_MODULES`.
A handler returns an exit code.  Any ``ValueError`` (bad input, bad option)
is printed as one line (at most :data:`MAX_MESSAGE` characters) on stderr and
exits with code 2 -- never a traceback.  Warnings (e.g. a diverged filter) are
printed as one plain sentence, without the source line Python adds.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings

__all__ = ["main", "COMMAND_MODULES", "MAX_MESSAGE", "one_line"]

#: Longest error line printed (longer messages keep their start and their end).
MAX_MESSAGE = 300

#: Modules that add sub-commands (each has ``register(subparsers)``).
COMMAND_MODULES: list[str] = [
    "shipid.commands.models",
    "shipid.commands.fit",
    "shipid.commands.demo",
    "shipid.commands.log",
    "shipid.commands.metrics",
    "shipid.commands.simulate",
    "shipid.commands.sweep",
    "shipid.commands.route",
    "shipid.commands.glider",
    "shipid.commands.validate",
    "shipid.commands.report",
    "shipid.commands.plan",
    "shipid.commands.sample",
    "shipid.commands.campaign",
    "shipid.commands.crossval",
]


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors -> exit 2, one line
        self.print_usage(sys.stderr)
        raise _UsageError(f"{self.prog}: error: {message}")


class _UsageError(Exception):
    pass


def build_parser() -> argparse.ArgumentParser:
    from . import __version__, _jit

    parser = _Parser(prog="shipid", description="Identify, validate and use ship manoeuvring models.")
    parser.add_argument("--version", action="version", version=f"shipid {__version__} ({_jit.path()})")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for mod in COMMAND_MODULES:
        importlib.import_module(mod).register(sub)
    return parser


def one_line(text: str, limit: int = MAX_MESSAGE) -> str:
    """``text`` on one line, at most ``limit`` characters (the middle elided: the start names the file,
    the end says what to do)."""
    msg = " ".join(str(text).split())
    if len(msg) <= limit:
        return msg
    head = limit * 2 // 3
    return msg[:head] + " ... " + msg[len(msg) - (limit - head - 5):]


def _input_files(args) -> str:
    """The existing files named on the command line (for errors that cannot say which one)."""
    import os

    names = []
    for key, val in sorted(vars(args).items()):
        if key in ("output", "trajectory", "handler"):
            continue
        for v in val if isinstance(val, list) else [val]:
            if isinstance(v, str) and v and os.path.isfile(v):
                names.append(os.path.basename(v))
    return ", ".join(names[:4]) + (" ..." if len(names) > 4 else "") if names else "no file named"


def _show_warning(prog: str):
    def show(message, category, filename, lineno, file=None, line=None):
        print(one_line(f"{prog}: warning: {message}"), file=sys.stderr if file is None else file)
    return show


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 numerical failure, 2 bad input)."""
    from ._io import install_signal_cleanup, restore_signal_handlers

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        print(one_line(str(exc)), file=sys.stderr)
        return 2
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    handlers = install_signal_cleanup()
    prog = f"shipid {args.command}"
    from . import _jit

    old_notices = _jit._notify[0]
    if not getattr(args, "quiet", False):  # "compiling ... (first run only)", "numba is not installed ..."
        _jit.set_notices(lambda line: print(f"shipid: {line}", file=sys.stderr, flush=True))
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning(prog)
    try:
        return int(args.handler(args) or 0)
    except BrokenPipeError:  # `shipid models | head`: the reader left; not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (ValueError, OSError) as exc:
        print(one_line(f"{prog}: error: {exc}"), file=sys.stderr)
        return 2
    except RecursionError:
        print(one_line(f"{prog}: error: an input file is nested too deeply to read ({_input_files(args)}); "
                       "check that it is the file you meant"), file=sys.stderr)
        return 2
    except OverflowError:
        print(one_line(f"{prog}: error: a number given is too large to compute with ({_input_files(args)}); "
                       "check the options and files"), file=sys.stderr)
        return 2
    except MemoryError:
        print(f"{prog}: error: out of memory; reduce the problem size (intervals, particles, samples)",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("shipid: interrupted", file=sys.stderr)
        return 130
    finally:
        _jit.set_notices(old_notices)
        warnings.showwarning = old_show
        restore_signal_handlers(handlers)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
