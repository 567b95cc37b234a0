"""Keep C++ libraries' stderr chatter out of taplan's own messages.

urdfdom prints its parse errors straight to file descriptor 2 (``Error: Joint [j] ... at line 607 in
joint.cpp``) before pinocchio raises; a command line must print one line of its own instead. :func:`native_stderr`
redirects fd 2 to a temporary file for the duration of a native call and hands the text back, so the caller can
quote its first error in the exception it raises.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator

__all__ = ["NativeOutput", "native_stderr"]


class NativeOutput:
    """What a native call wrote to stderr (filled in when the ``with`` block ends)."""

    def __init__(self) -> None:
        self.text = ""

    @property
    def first_error(self) -> str:
        """The first ``Error:`` line without its prefix, or the first line, or ``""``."""
        lines = [line.strip() for line in self.text.splitlines() if line.strip()]
        for line in lines:
            if line.lower().startswith("error:"):
                return line[6:].strip()
        return lines[0] if lines else ""


@contextlib.contextmanager
def native_stderr() -> Iterator[NativeOutput]:
    """Capture what native code writes to fd 2 inside the block (Python's ``sys.stderr`` is flushed first)."""
    output = NativeOutput()
    try:
        fd = sys.__stderr__.fileno() if sys.__stderr__ is not None else 2
        saved = os.dup(fd)
    except (OSError, ValueError, AttributeError):  # no real stderr (embedded interpreter): nothing to capture
        yield output
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os.dup2(sink.fileno(), fd)
        try:
            yield output
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            sink.seek(0)
            output.text = sink.read().decode("utf-8", "replace")
