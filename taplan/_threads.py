"""One thread for the BLAS and OpenMP pools while a planning call runs.

The planner's numerical work is many small array operations (a few dozen configurations, matrices of tens of rows):
OpenBLAS's worker threads (numpy's and scipy's own copies, 2 each on a 2-core machine) and pinocchio's OpenMP pool
cost more to wake and synchronise than they save on such sizes, and under load a worker that is not scheduled
stalls the caller. Measured on the timing and verification of 7 optimised paths of the benchmark (issue 22):
12.8 ms CPU with one BLAS thread against 21.6 ms with two, the same trajectories.

:func:`single_threaded` limits every pool the process has loaded to one thread for the duration of a ``with``
block and restores the previous settings afterwards. The limit is the process's (the pools are global): another
Python thread's BLAS calls made during the block run single-threaded too. The pools are found once (threadpoolctl
inspects the loaded libraries: ~12 ms); a limit then costs ~0.03 ms.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

__all__ = ["single_threaded", "run_single_threaded"]

_controller: Any = None
_F = TypeVar("_F", bound=Callable[..., Any])


def _pools() -> Any:
    """threadpoolctl's controller of the pools loaded so far, found on first use."""
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller


@contextmanager
def single_threaded() -> Iterator[None]:
    """Every BLAS / OpenMP pool at one thread inside the block; the previous numbers of threads afterwards."""
    with _pools().limit(limits=1):
        yield


def run_single_threaded(function: _F) -> _F:
    """``function`` called inside :func:`single_threaded` (a decorator)."""

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with single_threaded():
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
