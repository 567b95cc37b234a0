"""The ``taplan`` command line: ``taplan info | demo | plan | check | replay | run | sim | bench``.

Each subcommand lives in ``taplan/commands/<name>.py`` with ``add_arguments(parser)`` and ``run(args) -> int``; the
first line of its docstring is its help text. The CLI owns all output.

Exit codes: 0 success (a check passed), 1 a check failed, 2 bad input or usage (one line ``taplan CMD: error:
...`` on stderr), 3 an internal error (one line too; ``TAPLAN_DEBUG=1`` shows the traceback). A closed stdout (e.g.
``| head -1``) does not change the code: the rest of the output is discarded and the command finishes.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import re
import sys
import warnings
from collections.abc import Sequence
from typing import NoReturn, TextIO

import taplan

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_USAGE", "EXIT_INTERNAL"]

COMMANDS = ("info", "demo", "plan", "check", "replay", "run", "sim", "bench", "view")
EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERNAL = 0, 1, 2, 3


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line, ``taplan CMD: error: ...`` (``taplan -h`` / ``CMD -h`` show the usage)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} -h)\n")


def plain_text(doc: str) -> str:
    """A docstring as help text: RST roles and literals (``:func:`x```, ````x````) shown as plain ``x``."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", doc)
    return re.sub(r"``([^`]+)``", r"\1", text).strip()


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="taplan", description=plain_text(__doc__.splitlines()[0]))
    parser.add_argument("--version", action="version", version=f"taplan {taplan.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        if importlib.util.find_spec(f"taplan.commands.{name}") is None:
            continue
        module = importlib.import_module(f"taplan.commands.{name}")
        doc = plain_text(module.__doc__ or name)
        command = sub.add_parser(
            name, help=doc.splitlines()[0], description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        module.add_arguments(command)
        command.set_defaults(_run=module.run, _parser=command)
    return parser


class _PipeSafe:
    """A stdout that survives its reader going away: once a write hits a closed pipe, further output is dropped
    (fd 1 points at /dev/null so the interpreter's final flush is quiet) and the command runs to its verdict."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self.closed_pipe = False

    def write(self, text: str) -> int:
        if not self.closed_pipe:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._discard()
        return len(text)

    def flush(self) -> None:
        if not self.closed_pipe:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._discard()

    def _discard(self) -> None:
        self.closed_pipe = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):  # not a real file (tests capture stdout)
            pass

    def __getattr__(self, name: str):  # noqa: ANN204 - isatty, fileno, encoding... of the real stream
        return getattr(self._stream, name)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (see the module docstring)."""
    real_stdout = sys.stdout
    sys.stdout = safe = _PipeSafe(real_stdout)
    code = EXIT_USAGE
    try:
        with warnings.catch_warnings():  # numpy's overflow notes on absurd inputs: the verdict or error says it
            warnings.simplefilter("ignore", RuntimeWarning)
            code = _main(argv)
        return code
    finally:
        if sys.stdout is safe:
            safe.flush()
            sys.stdout = real_stdout
        command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
        if argv is None and command in _FAST_EXIT:
            _exit_now(code)


# Commands that talk to a robot end as soon as their work is done: the interpreter's teardown of the loaded
# libraries (pinocchio, casadi, Cyclone DDS) takes 2-4 s on a loaded machine, and a run whose robot crashed must
# end within a second. Their files are closed and their output flushed before; only taplan's own command line
# (argv None, i.e. ``taplan ...`` / ``python -m taplan ...``) exits this way, never a main([...]) call.
_FAST_EXIT = {"run", "sim"}


def _exit_now(code: int) -> None:
    import logging

    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(code))


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # reported by the subcommand, so the message names it
        getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(extra)}")
    if not hasattr(args, "_run"):
        parser.print_help()
        return EXIT_USAGE
    try:
        return int(args._run(args))
    except taplan.TaplanError as exc:
        return _error(args.command, str(exc), EXIT_USAGE)
    except OSError as exc:  # a file the command had to read or write
        where = f" {exc.filename!r}" if exc.filename else ""
        return _error(args.command, f"cannot access{where}: {exc.strerror or exc}", EXIT_USAGE)
    except KeyboardInterrupt:
        return _error(args.command, "interrupted", 130)
    except Exception as exc:  # noqa: BLE001 - a bug: one line, never a traceback, unless asked for
        if os.environ.get("TAPLAN_DEBUG"):
            raise
        message = f"internal error {type(exc).__name__}: {exc} (please report it; TAPLAN_DEBUG=1 shows the traceback)"
        return _error(args.command, message, EXIT_INTERNAL)


def _error(command: str, message: str, code: int) -> int:
    line = " ".join(message.split())  # one line, whatever the exception carried
    print(f"taplan {command}: error: {line}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
