"""A batch of independent populations: bounds, evaluation, best-so-far bookkeeping.

Backend-neutral: the populations live in the array library and on the device of the warm start
``x0`` (numpy, or torch on any device; :mod:`uav_formation_env.core.array_api`). Random factors
are drawn on the host from the numpy generators (so a seed draws the same numbers on either
backend) and moved to the device.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uav_formation_env.core.array_api import (
    as_float,
    asarray_like,
    copy,
    device,
    namespace_of,
    nan_to_inf,
)
from uav_formation_env.policies.optimizers.config import FITNESS_EPS, CostFn, OptimResult


def fitness(cost: np.ndarray) -> np.ndarray:
    """Fitness ``f = 1 / (max(J, 0) + 1e-12)``; ``+inf`` cost gives 0 (docs/model.md §6)."""
    return 1.0 / (np.maximum(cost, 0.0) + FITNESS_EPS)


def weighted_centre(x: np.ndarray, cost: np.ndarray, divide_by_count: bool = False) -> np.ndarray:
    """Fitness-weighted centre ``Σ f_i X_i / Σ f_i`` of a population.

    Args:
        x: ``(*batch, P, n)`` positions.
        cost: ``(*batch, P)`` their costs (NaN already mapped to ``+inf``).
        divide_by_count: Literal eq. 17/18: divide additionally by ``P``.

    Returns:
        ``(*batch, n)`` centres. If every cost is ``+inf`` the plain mean is used.
    """
    x = as_float(x)
    cost = as_float(cost, x)
    xp = namespace_of(x)
    batch = tuple(x.shape[:-2])
    flat_x = xp.reshape(x, (-1, *x.shape[-2:]))
    centre = weighted_centre_into(flat_x, xp.reshape(cost, flat_x.shape[:2]), divide_by_count)
    return xp.reshape(centre, (*batch, x.shape[-1]))


def weighted_centre_into(
    x: np.ndarray, cost: np.ndarray, divide_by_count: bool, work: np.ndarray | None = None
) -> np.ndarray:
    """:func:`weighted_centre` of ``x`` (B, P, n) and ``cost`` (B, P), the same operations.

    ``work`` is an optional (B, P, n) buffer for the weighted positions.
    """
    xp = namespace_of(x)
    # Fitness, normalised by the largest first: f can reach 1e12 (J = 0), the ratio is unchanged.
    f = xp.maximum(cost, 0.0)
    f += FITNESS_EPS
    f = 1.0 / f
    f_max = xp.max(f, axis=-1, keepdims=True)
    empty = f_max == 0.0  # every cost +inf: plain mean
    if bool(xp.any(empty)):
        f[empty[:, 0]] = 1.0
        f_max = xp.where(empty, 1.0, f_max)
    f /= f_max
    weighted = xp.multiply(f[..., None], x, out=work)
    centre = xp.sum(weighted, axis=-2)
    centre /= xp.sum(f, axis=-1)[..., None]
    if divide_by_count:
        centre /= x.shape[-2]
    return centre


class Population:
    """Flattening, clipping, counting and best-so-far bookkeeping for one :func:`minimise` call.

    Internally every array has one flat batch axis: populations are (B, P, n) with
    ``B = prod(batch)`` and ``n = prod(dims)``; the cost function sees them reshaped (a view).
    Arrays live in the library and on the device of ``x0`` (``xp``); the draws of ``rng`` (numpy,
    on the host) are moved there by :meth:`on_device`.
    """

    def __init__(self, cost_fn: CostFn, x0: Any, low, high, batch_ndim: int) -> None:
        x0 = as_float(x0)
        xp = self.xp = namespace_of(x0)
        if not 0 <= batch_ndim <= x0.ndim:
            raise ValueError(f"batch_ndim must be in [0, {x0.ndim}], got {batch_ndim}")
        shape = tuple(x0.shape)
        self.batch, self.dims = shape[:batch_ndim], shape[batch_ndim:]
        self.nb, self.n = math.prod(self.batch), math.prod(self.dims)
        lo = xp.broadcast_to(as_float(low, x0), shape)
        hi = xp.broadcast_to(as_float(high, x0), shape)
        finite = xp.all(xp.isfinite(lo)) and xp.all(xp.isfinite(hi))
        if not (bool(finite) and bool(xp.all(lo <= hi))):
            raise ValueError("low and high must be finite with low <= high")
        # (B, 1, n): broadcasts against populations (B, P, n).
        self.low = xp.reshape(lo, (self.nb, 1, self.n))
        self.high = xp.reshape(hi, (self.nb, 1, self.n))
        self.x0 = self.clip(xp.reshape(x0, (self.nb, 1, self.n)))
        self.rows = xp.arange(self.nb, device=device(x0))
        self.cost_fn = cost_fn
        self.n_evals = 0
        self.best_x = copy(self.x0[:, 0, :])  # (B, n), updated in place
        self.best_cost = xp.full(self.nb, xp.inf, dtype=x0.dtype, device=device(x0))
        self.initial_cost: Any = None

    def on_device(self, drawn: np.ndarray) -> Any:
        """Host draws ``drawn`` in the library and on the device of the populations (numpy: the
        array itself)."""
        return asarray_like(drawn, self.x0)

    def clip(self, x: Any, out: Any = None) -> Any:
        """``clip(x, low, high)`` as ``min(max(x, low), high)`` (what ``np.clip`` computes)."""
        out = self.xp.maximum(x, self.low, out=out)
        return self.xp.minimum(out, self.high, out=out)

    def full_bounds(self, size: int) -> tuple[Any, Any]:
        """``low`` and ``high`` materialised as contiguous (B, size, n) arrays (faster ufuncs)."""
        shape = (self.nb, size, self.n)
        return (
            copy(self.xp.broadcast_to(self.low, shape)),
            copy(self.xp.broadcast_to(self.high, shape)),
        )

    def rand(self, rng: np.random.Generator, size: int, per_dim: bool) -> Any:
        """U[0, 1) factors ``(B, size, n or 1)``: per component or one per pigeon."""
        return self.on_device(rng.random((self.nb, size, self.n if per_dim else 1)))

    def initial_population(self, rng: np.random.Generator, size: int) -> Any:
        """``(B, size, n)``: the warm start, then uniform samples in the box."""
        u = self.on_device(rng.random((self.nb, size - 1, self.n)))
        uniform = self.clip(self.low + (self.high - self.low) * u)
        return self.xp.concat([self.x0, uniform], axis=-2)

    def evaluate(self, x: Any) -> Any:
        """Cost ``(B, K)`` of ``x`` ``(B, K, n)`` in one call; updates the best."""
        xp, size = self.xp, x.shape[-2]
        cost = as_float(self.cost_fn(xp.reshape(x, (*self.batch, size, *self.dims))), x)
        if tuple(cost.shape) != (*self.batch, size):
            shape = tuple(cost.shape)
            raise ValueError(f"cost_fn returned shape {shape}, expected {(*self.batch, size)}")
        # A new array with NaN -> +inf: NaN can never become the best.
        cost = nan_to_inf(xp.reshape(cost, (self.nb, size)))
        self.n_evals += size
        if self.initial_cost is None:  # the first batch is the initial population, x0 first
            self.initial_cost = copy(cost[:, 0])
        i = xp.argmin(cost, axis=-1)
        # Strict '<': on ties the older point (ultimately x0, the initial best_x) is kept.
        better = cost[self.rows, i] < self.best_cost
        if bool(xp.any(better)):
            rows = self.rows[better]
            self.best_x[rows] = x[rows, i[rows]]
            self.best_cost[rows] = cost[rows, i[rows]]
        return cost

    def result(self) -> OptimResult:
        assert self.initial_cost is not None, "the initial population is always evaluated"
        xp = self.xp
        return OptimResult(
            x=xp.reshape(self.best_x, (*self.batch, *self.dims)),
            cost=xp.reshape(self.best_cost, self.batch),
            initial_cost=xp.reshape(self.initial_cost, self.batch),
            n_evals=self.n_evals,
        )
