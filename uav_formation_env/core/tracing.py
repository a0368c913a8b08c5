"""``torch.compile`` support of the core: whether code is being traced, the torch namespace
traced code uses, and compiled calls with an eager fallback (``SimOptions(compile=True)``;
docs/performance.md says what makes the step one graph).

torch is imported lazily: with numpy alone nothing here runs, and :func:`is_tracing` is False.
"""

from __future__ import annotations

import warnings
from typing import Any

_IS_COMPILING: list[Any] = []  # torch.compiler.is_dynamo_compiling, once torch_compiled ran


def is_tracing() -> bool:
    """Whether ``torch.compile`` is tracing the caller (False before :func:`torch_compiled`):
    code with a Python side effect that tracing would replay (a cache store) skips it then."""
    return bool(_IS_COMPILING) and _IS_COMPILING[0]()


class TracedTorch:
    """``array_api_compat.torch`` for code that ``torch.compile`` traces: the functions whose
    compat wrappers promote Python scalars through dtype queries (a graph break each) call
    torch directly, with the same results; every other name is the compat module's."""

    def __init__(self) -> None:
        import array_api_compat.torch as compat
        import torch

        self._compat, self._torch = compat, torch

    def __getattr__(self, name: str) -> Any:
        return getattr(self._compat, name)

    def where(self, condition: Any, x1: Any, x2: Any) -> Any:
        return self._torch.where(condition, x1, x2)

    def maximum(self, x1: Any, x2: Any) -> Any:
        return self._bound(x1, x2, "min", self._torch.maximum)

    def minimum(self, x1: Any, x2: Any) -> Any:
        return self._bound(x1, x2, "max", self._torch.minimum)

    def _bound(self, x1: Any, x2: Any, side: str, both: Any) -> Any:
        """``both(x1, x2)``; with a Python number on one side, the other clamped at it."""
        if isinstance(x2, (int, float)):
            return self._torch.clamp(x1, **{side: x2})
        if isinstance(x1, (int, float)):
            return self._torch.clamp(x2, **{side: x1})
        return both(x1, x2)

    def astype(self, x: Any, dtype: Any, copy: bool = True, device: Any = None) -> Any:
        return x.to(dtype=dtype, device=device)


_TRACED: list[TracedTorch] = []


def traced_einsum(subscripts: str, *operands: Any) -> Any:
    """``torch.einsum`` for traced code, except the product of two operands summed over their
    last axis (``"...k,...k->..."``): an elementwise product and a sum, which the compiler fuses
    with their neighbours (rather than a batched matrix product)."""
    import torch

    inputs, output = subscripts.replace(" ", "").split("->")
    terms = inputs.split(",")
    if len(terms) == 2 and terms[0] == terms[1] and terms[0][:-1] == output:
        first, second = operands
        return (first * second).sum(dim=-1)
    return torch.einsum(subscripts, *operands)


def traced_namespace() -> TracedTorch:
    if not _TRACED:
        _TRACED.append(TracedTorch())
    return _TRACED[0]


def torch_compiled(function: Any) -> Any:
    """``torch.compile(function)`` for fixed shapes (compiled lazily, at its first call; the
    core's one torch import stays in this module)."""
    import torch  # here with the torch backend, whose options checked that torch imports

    if not _IS_COMPILING:  # both set before any tracing: a traced check of them is then fixed
        _IS_COMPILING.append(torch.compiler.is_dynamo_compiling)
        traced_namespace()
    return torch.compile(function, dynamic=False)


def call_compiled(slot: list, function: Any, *args: Any) -> Any:
    """``function(*args)`` through :func:`torch_compiled`, compiled at the first call and kept in
    ``slot`` (a list, empty or holding it); where compilation fails, one ``RuntimeWarning`` and
    ``function`` itself from then on (the same numbers, eagerly)."""
    if not slot:
        slot.append(torch_compiled(function))
    try:
        with warnings.catch_warnings():  # the core's constants are cached: Dynamo says so, once
            warnings.filterwarnings("ignore", "Dynamo detected a call to a `functools.lru_cache`")
            return slot[0](*args)
    except Exception as error:  # noqa: BLE001 - any compiler failure: run eagerly instead
        if slot[0] == function:
            raise  # the eager function itself failed: a real error
        name = getattr(function, "__qualname__", "the step")
        warnings.warn(
            f"torch.compile of {name} failed ({type(error).__name__}: {error}); running it eagerly",
            RuntimeWarning,
            stacklevel=3,
        )
        slot[0] = function
        return function(*args)
