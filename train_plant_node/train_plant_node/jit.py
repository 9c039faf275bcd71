"""Optional just-in-time compilation of the plant's inner kernels.

The kernels (one integration step of a model, the line force of a segment, the varying
resistance factors) are plain Python functions on floats and preallocated numpy arrays. With
numba installed they are compiled to machine code on first use and cached on disk (in
``__pycache__`` next to the sources, or numba's per-user cache directory where that is not
writable); without it the same functions run as Python, much slower. There is one copy of the
physics either way.
"""

from __future__ import annotations

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is not installed
    numba = None  # type: ignore[assignment]

JIT_AVAILABLE = numba is not None


def kernel(function):
    """``numba.njit(cache=True)`` when numba is importable, else the function itself."""
    if numba is None:
        return function
    return numba.njit(cache=True)(function)
