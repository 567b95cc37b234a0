"""Run the benchmark suite and regenerate benchmarks/RESULTS.md (needs a source checkout).

Equivalent to ``python -m benchmarks`` from the repository root.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from taplan.errors import ConfigError, InvalidInputError

REPO = Path(__file__).resolve().parents[2]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="small sample counts (about a minute per benchmark)")
    parser.add_argument("--only", help="comma-separated subset, e.g. ik,stream")
    parser.add_argument("--report-only", action="store_true", help="rebuild RESULTS.md from the saved results")


def run(args: argparse.Namespace) -> int:
    if not (REPO / "benchmarks" / "__main__.py").exists():
        raise ConfigError(f"the benchmarks/ folder is not beside the installed package ({REPO}); run from a checkout")
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from benchmarks.__main__ import available, main

    if args.only is not None:  # checked here, so the error is taplan's one line
        names = available()
        unknown = [n for n in args.only.split(",") if n.strip() not in names]
        if unknown or not args.only.strip():
            raise InvalidInputError("--only", args.only, f"a comma-separated subset of {', '.join(names)}")
    argv = (["--quick"] if args.quick else []) + (["--only", args.only] if args.only else [])
    return main(argv + (["--report-only"] if args.report_only else []))
