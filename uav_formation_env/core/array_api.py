"""Array backends: how the core picks its array library, and the few operations the Python array
API standard lacks (the one shim module; docs/architecture.md, "Backends").

The core is written once against the array API standard (https://data-apis.org/array-api/): a
function takes arrays, asks :func:`namespace` for their library ``xp`` and calls ``xp.where``,
``xp.concat``, ``xp.cumulative_sum``... The same code then runs on

- **numpy** (the default and the only backend the base install needs). :func:`namespace` returns
  the ``numpy`` module itself: numpy >= 2.1 implements the standard's names in its main namespace,
  so the numpy path pays no wrapper (``array_api_compat.numpy`` re-exports the same functions,
  but its lookup costs ~1 us per call, a few percent of a B = 1 step);
- **torch** on CPU or CUDA, through ``array_api_compat.torch`` (``pip install
  uav-formation-env[rl]``).

Rules the core keeps so that one definition serves both (numpy and torch, not every library the
standard covers):

- new arrays name their dtype and device (``xp.zeros(shape, dtype=x.dtype, device=device(x))``):
  torch's default dtype is float32;
- no ``.T`` on more than 2 dimensions (torch refuses): :func:`move_batch_last` /
  ``xp.permute_dims``;
- copies through :func:`copy`; boolean and integer-array indexing and ``x[mask] = value`` as both
  libraries do them;
- what the standard lacks lives here: :func:`einsum`, :func:`add_at`, :func:`to_numpy`,
  :func:`namespace_of_backend`.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

__all__ = [
    "BACKENDS",
    "add_at",
    "copy",
    "device",
    "einsum",
    "is_numpy",
    "move_batch_first",
    "move_batch_last",
    "namespace",
    "namespace_of_backend",
    "to_numpy",
]

BACKENDS = ("numpy", "torch")  # the array libraries the core runs on

_PLAIN = (np.ndarray, np.generic, int, float, bool)  # values numpy takes as they are


def namespace(*arrays: Any) -> ModuleType:
    """The array library of ``arrays``: ``numpy`` itself when every one is a numpy array, a Python
    or numpy scalar or None; else ``array_api_compat``'s namespace of the others (torch).

    Raises:
        TypeError: arrays of two different libraries (names them).
    """
    others = [a for a in arrays if a is not None and not isinstance(a, _PLAIN)]
    if not others:
        return np
    from array_api_compat import array_namespace

    return array_namespace(*others)


def is_numpy(xp: ModuleType) -> bool:
    """True when ``xp`` is the numpy backend (for the few numpy-only speed paths)."""
    return xp is np


def namespace_of_backend(backend: str) -> ModuleType:
    """The namespace of a backend name (one of :data:`BACKENDS`).

    Raises:
        ValueError: an unknown name (lists the known ones).
        ImportError: torch is not installed (says how to install it).
    """
    if backend == "numpy":
        return np
    if backend == "torch":
        try:
            import torch  # noqa: F401  (the compat namespace imports it lazily)
        except ImportError as error:
            raise ImportError(
                "backend='torch' needs torch: pip install torch (CPU wheel first, see README), "
                "or pip install 'uav-formation-env[rl]'"
            ) from error
        import array_api_compat.torch as torch_namespace

        return torch_namespace
    raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")


def device(x: Any) -> Any:
    """The device of an array: ``"cpu"`` for numpy, ``tensor.device`` for torch."""
    if isinstance(x, _PLAIN):
        return "cpu"
    from array_api_compat import device as compat_device

    return compat_device(x)


def copy(x: Any) -> Any:
    """A new array with the values of ``x`` (never shares memory with it)."""
    if isinstance(x, np.ndarray):
        return x.copy()
    return x.clone()


def to_numpy(x: Any) -> np.ndarray:
    """``x`` as a numpy array (moved to the host for a CUDA tensor; shares memory on the CPU)."""
    if isinstance(x, np.ndarray):
        return x
    if isinstance(x, _PLAIN):
        return np.asarray(x)
    return x.detach().cpu().numpy()


def einsum(subscripts: str, *operands: Any) -> Any:
    """``einsum`` of numpy or torch (not in the standard; both libraries agree on the notation)."""
    xp = namespace(*operands)
    if is_numpy(xp):
        return np.einsum(subscripts, *operands)
    import torch

    return torch.einsum(subscripts, *operands)


def add_at(target: Any, index: Any, values: Any) -> None:
    """``target[index] += values`` with repeated indices accumulated, in place (``np.add.at``;
    torch ``index_put_(accumulate=True)``).

    Args:
        target: (M, ...) array, modified.
        index: (K,) integer indices into the first axis of ``target``.
        values: (K, ...) values, broadcastable to ``target[index]``.
    """
    if isinstance(target, np.ndarray):
        np.add.at(target, index, values)
        return
    target.index_put_((index,), values, accumulate=True)


def move_batch_last(x: Any) -> Any:
    """(B, ...) -> a contiguous copy laid out (..., B)."""
    if isinstance(x, np.ndarray):
        return x.transpose((*range(1, x.ndim), 0)).copy()  # np.moveaxis(x, 0, -1), cheaper
    import torch

    return x.permute((*range(1, x.ndim), 0)).clone(memory_format=torch.contiguous_format)


def move_batch_first(x: Any) -> Any:
    """(..., B) -> a (B, ...) view."""
    order = (x.ndim - 1, *range(x.ndim - 1))
    return x.transpose(order) if isinstance(x, np.ndarray) else x.permute(order)
