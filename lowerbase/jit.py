"""The project's one way to compile a numba kernel (lowerbase.world.raycast_kernel,
lowerbase.navigation.kernels): ``nopython``, ``nogil``, cached next to the module
(``__pycache__``, else numba's user-wide cache or ``NUMBA_CACHE_DIR``), and compiled in memory
where no cache location is writable. Import it only from kernel modules: it imports numba."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

F = TypeVar("F", bound=Callable[..., Any])


def compiled(**options: Any) -> Callable[[F], F]:
    """A decorator: ``fn`` compiled by ``numba.njit`` with ``options`` (e.g. error_model)."""
    def wrap(fn: F) -> F:
        try:
            return cast(F, numba.njit(cache=True, nogil=True, **options)(fn))
        except RuntimeError:  # "cannot cache function ...: no locator available" (read-only)
            return cast(F, numba.njit(nogil=True, **options)(fn))
    return wrap
