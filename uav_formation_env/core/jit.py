"""numba compilation with its on-disk cache where one can be written, in memory otherwise."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def njit_cached(numba: Any, fn: Callable) -> Callable:
    """``numba.njit(cache=True)(fn)``; where numba finds no writable cache folder (a read-only
    install and ``$HOME``, no ``NUMBA_CACHE_DIR``) it refuses at decoration time, so compile
    without the cache instead (each process compiles once, on first call)."""
    try:
        return numba.njit(cache=True)(fn)
    except RuntimeError as error:
        if "cannot cache" not in str(error):
            raise
        return numba.njit(fn)
