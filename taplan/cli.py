"""The ``taplan`` command line: ``taplan info | demo | plan | check | replay | run | sim | bench``.

Each subcommand lives in ``taplan/commands/<name>.py`` with ``add_arguments(parser)`` and ``run(args) -> int``; the
first line of its docstring is its help text. The CLI owns all output.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from collections.abc import Sequence

import taplan

__all__ = ["main", "build_parser"]

COMMANDS = ("info", "demo", "plan", "check", "replay", "run", "sim", "bench", "view")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="taplan", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"taplan {taplan.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if importlib.util.find_spec(f"taplan.commands.{name}") is None:
            continue
        module = importlib.import_module(f"taplan.commands.{name}")
        summary = (module.__doc__ or name).strip().splitlines()[0]
        command = sub.add_parser(name, help=summary, description=(module.__doc__ or "").strip())
        module.add_arguments(command)
        command.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    try:
        return int(args._run(args))
    except taplan.TaplanError as exc:
        print(f"taplan {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. head)
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
