"""Deterministic linear algebra for the controller.

A multithreaded BLAS splits its sums across threads, so the planner's and the Riccati solver's
numpy calls give results that differ in the last bits with the number of BLAS threads; over
rough ground the planner's optimiser amplifies those bits into other footholds. Everything the
controller computes with numpy therefore runs on one BLAS thread (:func:`one_blas_thread`), so
the same seed gives the same episode on any machine setting and in any worker (the planner's
problems are small: a second thread would not speed them up).
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Callable
from typing import Any, TypeVar

from threadpoolctl import ThreadpoolController

__all__ = ["one_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])

_controller: ThreadpoolController | None = None
_depth = threading.local()  # per thread: calls under way inside the limit


def one_blas_thread(func: F) -> F:
    """Decorator: run ``func`` with the BLAS libraries of the process on one thread (restored
    afterwards; calls may nest, and a nested call runs inside its caller's limit)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        global _controller
        depth = getattr(_depth, "n", 0)
        if depth:  # inside a caller's limit already
            limit = contextlib.nullcontext()
        else:
            if _controller is None:  # found once: the BLAS libraries numpy and scipy loaded
                _controller = ThreadpoolController()
            limit = _controller.limit(limits=1, user_api="blas")
        with limit:
            _depth.n = depth + 1
            try:
                return func(*args, **kwargs)
            finally:
                _depth.n = depth

    return wrapper  # type: ignore[return-value]
