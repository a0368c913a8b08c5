"""A batch of independent populations: bounds, evaluation, best-so-far bookkeeping."""

from __future__ import annotations

import math

import numpy as np

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
    x = np.asarray(x, dtype=np.float64)
    cost = np.asarray(cost, dtype=np.float64)
    batch = x.shape[:-2]
    flat_x = x.reshape(-1, *x.shape[-2:])
    centre = weighted_centre_into(flat_x, cost.reshape(flat_x.shape[:2]), divide_by_count)
    return centre.reshape(*batch, x.shape[-1])


def weighted_centre_into(
    x: np.ndarray, cost: np.ndarray, divide_by_count: bool, work: np.ndarray | None = None
) -> np.ndarray:
    """:func:`weighted_centre` of ``x`` (B, P, n) and ``cost`` (B, P), the same operations.

    ``work`` is an optional (B, P, n) buffer for the weighted positions.
    """
    # Fitness, normalised by the largest first: f can reach 1e12 (J = 0), the ratio is unchanged.
    f = np.maximum(cost, 0.0)
    f += FITNESS_EPS
    np.divide(1.0, f, out=f)
    f_max = f.max(axis=-1, keepdims=True)
    empty = f_max == 0.0  # every cost +inf: plain mean
    if empty.any():
        f[empty[:, 0]] = 1.0
        f_max = np.where(empty, 1.0, f_max)
    np.divide(f, f_max, out=f)
    weighted = np.multiply(f[..., None], x, out=work)
    centre = weighted.sum(axis=-2)
    centre /= f.sum(axis=-1)[..., None]
    if divide_by_count:
        centre /= x.shape[-2]
    return centre


class Population:
    """Flattening, clipping, counting and best-so-far bookkeeping for one :func:`minimise` call.

    Internally every array has one flat batch axis: populations are (B, P, n) with
    ``B = prod(batch)`` and ``n = prod(dims)``; the cost function sees them reshaped (a view).
    """

    def __init__(self, cost_fn: CostFn, x0: np.ndarray, low, high, batch_ndim: int) -> None:
        x0 = np.asarray(x0, dtype=np.float64)
        if not 0 <= batch_ndim <= x0.ndim:
            raise ValueError(f"batch_ndim must be in [0, {x0.ndim}], got {batch_ndim}")
        self.batch, self.dims = x0.shape[:batch_ndim], x0.shape[batch_ndim:]
        self.nb, self.n = math.prod(self.batch), math.prod(self.dims)
        lo = np.broadcast_to(np.asarray(low, dtype=np.float64), x0.shape)
        hi = np.broadcast_to(np.asarray(high, dtype=np.float64), x0.shape)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            raise ValueError("low and high must be finite with low <= high")
        # (B, 1, n): broadcasts against populations (B, P, n).
        self.low = np.ascontiguousarray(lo).reshape(self.nb, 1, self.n)
        self.high = np.ascontiguousarray(hi).reshape(self.nb, 1, self.n)
        self.x0 = self.clip(x0.reshape(self.nb, 1, self.n))
        self.rows = np.arange(self.nb)
        self.cost_fn = cost_fn
        self.n_evals = 0
        self.best_x = self.x0[:, 0, :].copy()  # (B, n), updated in place
        self.best_cost = np.full(self.nb, np.inf)
        self.initial_cost: np.ndarray | None = None

    def clip(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``clip(x, low, high)`` as ``min(max(x, low), high)`` (what ``np.clip`` computes)."""
        out = np.maximum(x, self.low, out=out)
        return np.minimum(out, self.high, out=out)

    def full_bounds(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        """``low`` and ``high`` materialised as contiguous (B, size, n) arrays (faster ufuncs)."""
        shape = (self.nb, size, self.n)
        return (
            np.ascontiguousarray(np.broadcast_to(self.low, shape)),
            np.ascontiguousarray(np.broadcast_to(self.high, shape)),
        )

    def rand(self, rng: np.random.Generator, size: int, per_dim: bool) -> np.ndarray:
        """U[0, 1) factors ``(B, size, n or 1)``: per component or one per pigeon."""
        return rng.random((self.nb, size, self.n if per_dim else 1))

    def initial_population(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """``(B, size, n)``: the warm start, then uniform samples in the box."""
        u = rng.random((self.nb, size - 1, self.n))
        uniform = self.clip(self.low + (self.high - self.low) * u)
        return np.concatenate([self.x0, uniform], axis=-2)

    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """Cost ``(B, K)`` of ``x`` ``(B, K, n)`` in one call; updates the best."""
        size = x.shape[-2]
        cost = np.asarray(self.cost_fn(x.reshape(*self.batch, size, *self.dims)), dtype=np.float64)
        if cost.shape != (*self.batch, size):
            raise ValueError(f"cost_fn returned shape {cost.shape}, expected {(*self.batch, size)}")
        # A new array with NaN -> +inf (fmin ignores NaN): NaN can never become the best.
        cost = np.fmin(cost.reshape(self.nb, size), np.inf)
        self.n_evals += size
        if self.initial_cost is None:  # the first batch is the initial population, x0 first
            self.initial_cost = cost[:, 0].copy()
        i = cost.argmin(axis=-1)
        # Strict '<': on ties the older point (ultimately x0, the initial best_x) is kept.
        better = cost[self.rows, i] < self.best_cost
        if better.any():
            rows = self.rows[better]
            self.best_x[rows] = x[rows, i[rows]]
            self.best_cost[rows] = cost[rows, i[rows]]
        return cost

    def result(self) -> OptimResult:
        assert self.initial_cost is not None, "the initial population is always evaluated"
        return OptimResult(
            x=self.best_x.reshape(*self.batch, *self.dims),
            cost=self.best_cost.reshape(self.batch),
            initial_cost=self.initial_cost.reshape(self.batch),
            n_evals=self.n_evals,
        )
