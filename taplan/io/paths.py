"""The output-path rule and the rate range shared by every command.

A command writes where it is told: a missing parent directory is created, an existing file is replaced unless the
caller forbids it, and a path whose suffix the command cannot write is refused before any work is done (so nothing
fails after printing a verdict).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from taplan.errors import ConfigError, InvalidInputError

__all__ = ["MAX_RATE", "bounded_rate", "output_path"]

MIN_RATE = 1.0  # [Hz]: below this a sampled stream no longer describes a robot motion
MAX_RATE = 10_000.0  # [Hz]: ten times the fastest controller modelled; keeps a sampled file within memory


def output_path(
    path: str | Path,
    argument: str,
    *,
    suffixes: Sequence[str] | None = None,
    overwrite: bool = True,
    directory: bool = False,
) -> Path:
    """``path`` made ready for writing: its parent directories created, its suffix and existence checked.

    Args:
        path: Where the command will write.
        argument: The option that named it (for the error message), e.g. ``"--png"``.
        suffixes: Accepted suffixes (lower case, with the dot), None = any.
        overwrite: Whether an existing file may be replaced.
        directory: The path is a directory to create (an existing file there is an error).

    Raises:
        InvalidInputError: wrong suffix, or an existing file that may not be replaced.
        ConfigError: the directory cannot be created (e.g. a file is in the way, no permission).
    """
    out = Path(path)
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise InvalidInputError(argument, str(out), f"a file name ending in {', '.join(suffixes)}")
    if out.is_dir() and not directory:
        raise InvalidInputError(argument, str(out), "a file path (this is a directory)")
    if directory and out.exists() and not out.is_dir():
        raise InvalidInputError(argument, str(out), "a directory (a file of that name exists)")
    if not directory and out.exists() and not overwrite:
        raise InvalidInputError(argument, str(out), "a path that does not exist yet (will not overwrite a file)")
    target = out if directory else out.parent
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{argument}: cannot create directory {str(target)!r}: {exc.strerror or exc}") from None
    return out


def bounded_rate(value: float, argument: str, low: float = MIN_RATE, high: float = MAX_RATE) -> float:
    """``value`` as a rate [Hz] within ``[low, high]``, or an error naming ``argument`` and the range."""
    try:
        rate = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(argument, value, f"a rate in [{low:g}, {high:g}] Hz") from None
    if not math.isfinite(rate) or not low <= rate <= high:
        raise InvalidInputError(argument, value, f"a rate in [{low:g}, {high:g}] Hz")
    return rate
