"""Array backends: how the core picks its array library, and the few operations the Python array
API standard lacks (the one shim module; docs/architecture.md, "Backends").

The core is written once against the array API standard (https://data-apis.org/array-api/): a
function takes arrays, asks :func:`namespace` for their library ``xp`` and calls ``xp.where``,
``xp.concat``, ``xp.cumulative_sum``... The same code then runs on

- **numpy** (the default and the only backend the base install needs). :func:`namespace` returns
  the ``numpy`` module itself (numpy >= 2.1 has the standard's names): no wrapper on numpy;
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
- what the standard lacks, or numpy spells faster, lives here: backend and device choice
  (:func:`namespace_of_backend`, :func:`backend_device`), conversions (:func:`to_numpy`,
  :func:`asarray_like`, :func:`as_float`, :func:`constant_like` for cached configuration arrays),
  ``einsum`` (:func:`einsum`, :func:`einsum_in`, :func:`einsum_function`), :func:`take`,
  :func:`add_at`, :func:`amin`, in-place writes (:func:`subtract_into`, :func:`clip_in_place`)
  and the batch-axis moves, and what keeps the core one ``torch.compile`` graph (:func:`may_hold`,
  :func:`read_only`, :mod:`~uav_formation_env.core.tracing`). Each numpy-only branch carries its
  measured reason.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from uav_formation_env.core.tracing import TracedTorch, is_tracing, traced_einsum, traced_namespace

__all__ = [
    "BACKENDS",
    "add_at",
    "amin",
    "as_float",
    "asarray_like",
    "backend_device",
    "clip_in_place",
    "concat_into",
    "constant_like",
    "copy",
    "copy_where",
    "device",
    "einsum",
    "einsum_function",
    "einsum_in",
    "float_dtype",
    "is_numpy",
    "may_hold",
    "move_batch_first",
    "move_batch_last",
    "namespace",
    "nan_to_inf",
    "read_only",
    "namespace_of",
    "namespace_of_backend",
    "subtract_into",
    "take",
    "to_numpy",
    "torch_device",
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
    if is_tracing():
        return traced_namespace()
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
        if is_tracing():
            return traced_namespace()
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
    return einsum_function(namespace(*operands))(subscripts, *operands)


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


def einsum_in(xp: ModuleType, subscripts: str, *operands: Any) -> Any:
    """:func:`einsum` in a namespace the caller already has (skips the :func:`namespace` lookup:
    stage_cost makes six calls)."""
    return einsum_function(xp)(subscripts, *operands)


def asarray_like(a: Any, like: Any) -> Any:
    """``a`` in the library, dtype and device of ``like``, for arrays a caller may hand over as
    numpy whatever the backend (formation offsets and adjacency from the config).

    Returns ``a`` itself, unconverted, when ``like`` is a numpy array (the numpy path pays
    nothing). Otherwise a tensor of ``like``'s dtype on its device: ``a`` itself when it is one
    already, a copy of a numpy ``a`` (cached read-only numpy arrays cannot be shared with torch).
    """
    if isinstance(like, _PLAIN):
        return a
    xp = namespace(like)
    if isinstance(a, np.ndarray):
        a = np.array(a)  # writable copy: torch warns on sharing read-only memory
    return xp.asarray(a, dtype=like.dtype, device=device(like))


def take(x: Any, index: Any, axis: int = 0) -> Any:
    """``np.take``: the entries ``index`` (an integer array of any shape) along ``axis``, as a new
    array of shape ``x.shape[:axis] + index.shape + x.shape[axis+1:]`` (the standard's ``take``
    and torch's ``index_select`` accept 1-D indices only)."""
    if isinstance(x, np.ndarray):
        return x.take(index, axis=axis)
    import torch

    index = torch.as_tensor(index, device=x.device)
    flat = torch.index_select(x, axis, index.reshape(-1))
    axis %= x.ndim
    return flat.reshape((*x.shape[:axis], *index.shape, *x.shape[axis + 1 :]))


def float_dtype(like: Any) -> Any:
    """The float dtype for new arrays computed from ``like``: its own dtype when it is a floating
    array, else float64 (numpy's default; torch's default float32 would lose precision)."""
    if isinstance(like, (np.ndarray, np.generic)) and like.dtype.kind == "f":
        return like.dtype
    if isinstance(like, _PLAIN) or like is None:
        return np.float64
    import torch

    return like.dtype if like.is_floating_point() else torch.float64


_NUMPY_INPUTS = (*_PLAIN, list, tuple)  # what as_float turns into numpy arrays


def as_float(x: Any, like: Any = None) -> Any:
    """``x`` as a floating array of the library and device of ``like`` (default: of ``x``).

    numpy (``like`` numpy, a scalar or None, and ``x`` not a tensor): ``np.asarray(x,
    dtype=float)`` exactly. torch: a floating tensor stays as it is (no copy); anything else
    (ints, numpy arrays, Python scalars) becomes a tensor of :func:`float_dtype` of ``like`` on
    ``like``'s device.
    """
    if like is None:
        like = x
    if isinstance(like, _NUMPY_INPUTS) and isinstance(x, _NUMPY_INPUTS):
        return np.asarray(x, dtype=float)
    import torch

    if isinstance(like, _PLAIN):  # x is the tensor
        like = x
    if isinstance(x, torch.Tensor) and x.is_floating_point() and x.device == like.device:
        return x
    dtype = float_dtype(like) if isinstance(like, torch.Tensor) else torch.float64
    if isinstance(x, np.ndarray):
        x = np.array(x)  # writable copy: torch warns on sharing read-only memory
    return torch.as_tensor(x, dtype=dtype, device=like.device)


_CONSTANTS: dict[tuple[int, str, str], tuple[np.ndarray, Any]] = {}


def constant_like(a: np.ndarray, like: Any) -> Any:
    """A cached, read-only numpy constant (configuration arrays such as ``schedule_arrays``) in
    the library and on the device of ``like``.

    numpy ``like`` (or a scalar, None): ``a`` itself, no conversion. torch: a tensor on ``like``'s
    device, floats in :func:`float_dtype` of ``like``, other dtypes kept; converted once per
    (array, device, dtype) and cached (a host-to-device copy per call would dominate on CUDA), so
    the result is shared: never write to it.
    """
    if isinstance(like, _PLAIN) or like is None:
        return a
    import torch

    if is_tracing():  # a constant of the graph (the cache below reads ndarray attributes)
        value = torch.as_tensor(a, device=like.device)
        return value.to(float_dtype(like)) if value.dtype.is_floating_point else value
    dtype = float_dtype(like) if a.dtype.kind == "f" else None
    key = (id(a), str(like.device), str(dtype))
    hit = _CONSTANTS.get(key)
    if hit is not None and hit[0] is a:
        return hit[1]
    value = torch.as_tensor(np.array(a), dtype=dtype, device=like.device)
    if len(_CONSTANTS) >= 256:
        _CONSTANTS.clear()
    _CONSTANTS[key] = (a, value)  # the entry holds `a`, so its id is not reused meanwhile
    return value


def backend_device(backend: str, device: Any = None) -> Any:
    """The device of arrays of ``backend``: ``"cpu"`` for numpy (the only one it has); a
    ``torch.device`` for torch (default CPU).

    Raises:
        ValueError: a device numpy does not have, or a name torch does not know (names it).
    """
    if backend == "numpy":
        if device not in (None, "cpu"):
            raise ValueError(f"backend='numpy' runs on device 'cpu' only, got device={device!r}")
        return "cpu"
    namespace_of_backend(backend)  # a clear error if torch is missing
    import torch

    try:
        return torch.device("cpu" if device is None else device)
    except (RuntimeError, TypeError) as error:
        message = f"device must name a torch device such as 'cuda', got {device!r}"
        raise ValueError(message) from error


def may_hold(mask: Any) -> bool:
    """Whether some element of ``mask`` is True, for a branch that only skips work the general
    path would do anyway: ``bool(mask.any())``, except while ``torch.compile`` traces, where it
    is True (the general path, no data-dependent branch in the graph)."""
    if type(mask) is np.ndarray or not is_tracing():
        return bool(mask.any())
    return True


def read_only(*arrays: np.ndarray) -> None:
    """Mark cached numpy constants read-only; not while ``torch.compile`` traces (Dynamo turns
    them into constants of the graph and cannot set ndarray flags)."""
    if is_tracing():
        return
    for array in arrays:
        array.flags.writeable = False


def torch_device(device: Any = None) -> Any:
    """The torch device a run asks for: ``device`` (checked as :func:`backend_device` does), or
    for None CUDA when torch sees a GPU, else the CPU."""
    if device is None:
        namespace_of_backend("torch")  # a clear error if torch is missing
        import torch

        device = "cuda" if torch.cuda.is_available() else "cpu"
    return backend_device("torch", device)


def namespace_of(x: Any) -> ModuleType:
    """:func:`namespace` of one array, with a numpy array answered by a type test first: the
    general lookup is slower, and the stage cost asks eight times; anything else goes through
    :func:`namespace`."""
    if type(x) is np.ndarray:
        return np
    return namespace(x)


# Appended for the observation encoders (core/observation.py, core/local_observation.py): in-place
# writes that the standard has no ``out=`` for. On numpy a fresh temporary of ~0.5 MB costs
# several times the arithmetic in page faults (benchmarks/bench_env.py).
def subtract_into(out: Any, x1: Any, x2: Any) -> None:
    """``out[...] = x1 - x2`` (broadcast to ``out``'s shape), in place; on numpy without a
    temporary. ``out`` may be a view (e.g. a slice of a larger array), which is then filled."""
    if isinstance(out, np.ndarray):
        np.subtract(x1, x2, out=out)
        return
    out[...] = x1 - x2


def clip_in_place(x: Any, low: Any, high: Any) -> None:
    """``x = minimum(maximum(x, low), high)`` in place (NaN stays NaN), with ``low`` and ``high``
    scalars or arrays broadcastable to ``x``."""
    if isinstance(x, np.ndarray):
        np.maximum(x, low, out=x)
        np.minimum(x, high, out=x)
        return
    x.clamp_(min=low, max=high)


def einsum_function(xp: ModuleType) -> Any:
    """The ``einsum`` callable of a namespace (``np.einsum`` or ``torch.einsum``), for a function
    that makes several calls: each then pays no wrapper (:func:`einsum_in` adds one)."""
    if is_numpy(xp):
        return np.einsum
    if isinstance(xp, TracedTorch):
        return traced_einsum
    import torch

    return torch.einsum


def amin(x: Any, axis: int, keepdims: bool = False) -> Any:
    """Minimum along ``axis`` (``xp.min``): ``np.minimum.reduce`` on numpy (np.min and the
    method add a Python layer), ``torch.amin`` on torch
    (the method ``tensor.min(dim)`` returns values and indices)."""
    if isinstance(x, np.ndarray):
        return np.minimum.reduce(x, axis=axis, keepdims=keepdims)
    import torch

    return torch.amin(x, dim=axis, keepdim=keepdims)


# Appended for the optimisers (policies/optimizers/): their loops work in preallocated buffers
# (docs of that package: at the DMPC's sizes an iteration is per-call overhead).
def copy_where(dst: Any, src: Any, mask: Any) -> None:
    """``dst[mask] = src[mask]`` in place, ``mask`` broadcast to ``dst`` (``np.copyto(where=)``)."""
    if isinstance(dst, np.ndarray):
        np.copyto(dst, src, where=mask)
        return
    dst.copy_(dst.where(~mask, src))


def concat_into(out: Any, arrays: tuple[Any, ...], axis: int) -> Any:
    """``concat(arrays, axis)`` written into ``out`` (the standard's ``concat`` has no ``out``)."""
    if isinstance(out, np.ndarray):
        return np.concatenate(arrays, axis=axis, out=out)
    import torch

    return torch.cat(arrays, dim=axis, out=out)


def nan_to_inf(x: Any) -> Any:
    """A new array with NaN replaced by +inf (``np.fmin(x, inf)``: NaN can never be a minimum)."""
    if isinstance(x, np.ndarray):
        return np.fmin(x, np.inf)
    import torch

    return torch.where(torch.isnan(x), torch.inf, x)
