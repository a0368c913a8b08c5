"""LFPIO's per-iteration bookkeeping as two kernels, compiled with numba when available.

With the ``[fast]`` extra the kernels run compiled; they give the same numbers as the numpy
reference :func:`~uav_formation_env.policies.optimizers.search.lfpio_search`.
"""

from __future__ import annotations

import math
import os

import numpy as np

from uav_formation_env.core.jit import njit_cached
from uav_formation_env.policies.optimizers.config import FITNESS_EPS, LFPIOConfig
from uav_formation_env.policies.optimizers.levy import (
    TINY,
    levy_denominator_into,
    mantegna_sigma,
)
from uav_formation_env.policies.optimizers.population import Population, weighted_centre_into

try:  # pragma: no cover - exercised when the [fast] extra is installed
    if os.environ.get("UAV_FORMATION_NO_NUMBA"):
        raise ImportError("disabled by UAV_FORMATION_NO_NUMBA")
    import numba
except ImportError:  # pragma: no cover
    numba = None

COMPILED_AVAILABLE = numba is not None  # LFPIO's bookkeeping can run as compiled kernels


def lfpio_move(
    x: np.ndarray,
    v: np.ndarray,
    best_x: np.ndarray,
    centre: np.ndarray,
    rand: np.ndarray,
    mu: np.ndarray,
    den: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    decay: float,
    sigma: float,
    levy_scale: float,
    both: np.ndarray,
) -> None:
    """One LFPIO move (eq. 18) in place, the operations of :func:`lfpio_search` per component.

    Shapes: x, v, mu, den (B, P, n); best_x, centre, low, high (B, n); rand (B, P, 1 or n);
    both (B, 2P, n) receives ``[Y1, Y2]``; x receives Y1 and v the new velocity. ``mu`` holds the
    raw N(0, 1) numerator draws and ``den`` the denominators ``|nu|**(1/beta)``.
    """
    nb, p, n = x.shape
    per_dim = rand.shape[2] != 1
    for b in range(nb):
        for i in range(p):
            for k in range(n):
                xi = x[b, i, k]
                to_centre = centre[b, k] - xi
                to_best = best_x[b, k] - xi
                to_best = (rand[b, i, k] if per_dim else rand[b, i, 0]) * to_best
                vel = v[b, i, k] * decay
                vel = vel + to_best
                v[b, i, k] = vel
                y1 = xi + vel
                if y1 < low[b, k]:
                    y1 = low[b, k]
                if y1 > high[b, k]:
                    y1 = high[b, k]
                step = mu[b, i, k] * sigma
                d = den[b, i, k]
                if d < TINY:
                    d = TINY
                step = step / d
                step = levy_scale * step
                step = step * to_centre
                y2 = y1 + step
                if y2 < low[b, k]:
                    y2 = low[b, k]
                if y2 > high[b, k]:
                    y2 = high[b, k]
                x[b, i, k] = y1
                both[b, i, k] = y1
                both[b, p + i, k] = y2


def _pairwise_sum(a: np.ndarray) -> float:
    """``a.sum()`` of a contiguous 1-d float64 array in numpy's own order (pairwise summation:
    8 accumulators per block of <= 128, halving above), so the kernel matches numpy bit for bit."""
    n = a.shape[0]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    if n <= 128:
        r0, r1, r2, r3 = a[0], a[1], a[2], a[3]
        r4, r5, r6, r7 = a[4], a[5], a[6], a[7]
        full = n - n % 8
        i = 8
        while i < full:
            r0 += a[i]
            r1 += a[i + 1]
            r2 += a[i + 2]
            r3 += a[i + 3]
            r4 += a[i + 4]
            r5 += a[i + 5]
            r6 += a[i + 6]
            r7 += a[i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[i]
            i += 1
        return res
    half = n // 2
    half -= half % 8
    return _pairwise_sum(a[:half]) + _pairwise_sum(a[half:])


def lfpio_select(
    both: np.ndarray,
    raw_cost: np.ndarray,
    x: np.ndarray,
    cost: np.ndarray,
    best_x: np.ndarray,
    best_cost: np.ndarray,
    centre: np.ndarray,
    weights: np.ndarray,
    divide_by_count: bool,
) -> None:
    """After the cost call: best-so-far update, greedy Y1/Y2 choice and the new weighted centre.

    In place; the operations of ``Population.evaluate`` and :func:`weighted_centre_into` per
    problem.

    Shapes: both (B, 2P, n); raw_cost (B, 2P) as returned (NaN is read as +inf); x (B, P, n)
    holds Y1 and receives X_l; cost (B, P) receives its costs; best_x (B, n); best_cost (B,);
    centre (B, n); weights (P,) scratch. Needs n >= 2 (numpy sums (B, P, 1) arrays pairwise).
    """
    nb, p2, n = both.shape
    p = p2 // 2
    inf = np.inf
    for b in range(nb):
        # Best so far: first minimum of the whole population, strict '<' against the old best.
        arg, lowest = 0, inf
        for j in range(p2):
            c = raw_cost[b, j]
            if c != c:
                c = inf
            if j == 0 or c < lowest:
                arg, lowest = j, c
        if lowest < best_cost[b]:
            best_cost[b] = lowest
            for k in range(n):
                best_x[b, k] = both[b, arg, k]
        # Greedy between the two candidates of each pigeon (Y1 is already in x).
        for i in range(p):
            c1, c2 = raw_cost[b, i], raw_cost[b, p + i]
            if c1 != c1:
                c1 = inf
            if c2 != c2:
                c2 = inf
            if c2 < c1:
                cost[b, i] = c2
                for k in range(n):
                    x[b, i, k] = both[b, p + i, k]
            else:
                cost[b, i] = c1
        # Fitness-weighted centre, normalised by the largest fitness.
        f_max = 0.0
        for i in range(p):
            c = cost[b, i]
            if c < 0.0:
                c = 0.0
            c += FITNESS_EPS
            weights[i] = 1.0 / c
            if i == 0 or weights[i] > f_max:
                f_max = weights[i]
        if f_max == 0.0:  # every cost +inf: plain mean
            f_max = 1.0
            weights[:] = 1.0
        for i in range(p):
            weights[i] = weights[i] / f_max
        total = 0.0 + _pairwise_sum(weights)
        for k in range(n):
            acc = weights[0] * x[b, 0, k]
            for i in range(1, p):
                acc += weights[i] * x[b, i, k]
            acc = acc / total
            if divide_by_count:
                acc = acc / p
            centre[b, k] = acc


if COMPILED_AVAILABLE:  # pragma: no branch
    _pairwise_sum = njit_cached(numba, _pairwise_sum)
    _lfpio_move_compiled = njit_cached(numba, lfpio_move)
    _lfpio_select_compiled = njit_cached(numba, lfpio_select)


def lfpio_search_compiled(run: Population, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    """:func:`lfpio_search` with the per-iteration bookkeeping in two compiled kernels.

    The random draws (same calls, same order), the Lévy denominators (numpy's own ``cbrt`` /
    ``power``) and the cost calls stay in numpy; every other operation is repeated per
    component in the same order, so the result is the same, bit for bit (tested).
    """
    p = cfg.n_pigeons
    x = np.ascontiguousarray(run.initial_population(rng, p))
    cost = np.ascontiguousarray(run.evaluate(x))
    v = np.zeros_like(x)
    levy = np.empty((2, *x.shape))
    both = np.empty((run.nb, 2 * p, run.n))
    weights = np.empty(p)
    low, high = run.low[:, 0], run.high[:, 0]
    centre = np.ascontiguousarray(weighted_centre_into(x, cost, cfg.center_divide_by_np))
    sigma = mantegna_sigma(cfg.levy_beta)
    population = (*run.batch, 2 * p, *run.dims)
    for it in range(1, cfg.iters + 1):
        rand = run.rand(rng, p, cfg.per_dimension_rand)
        rng.standard_normal(out=levy)
        levy_denominator_into(levy[1], cfg.levy_beta)
        _lfpio_move_compiled(
            x,
            v,
            run.best_x,
            centre,
            rand,
            levy[0],
            levy[1],
            low,
            high,
            math.exp(-cfg.map_compass_factor * it),
            sigma,
            cfg.levy_scale,
            both,
        )
        raw = np.asarray(run.cost_fn(both.reshape(population)), dtype=np.float64)
        if raw.shape != population[: len(run.batch) + 1]:
            raise ValueError(
                f"cost_fn returned shape {raw.shape}, expected {population[: len(run.batch) + 1]}"
            )
        run.n_evals += 2 * p
        _lfpio_select_compiled(
            both,
            np.ascontiguousarray(raw.reshape(run.nb, 2 * p)),
            x,
            cost,
            run.best_x,
            run.best_cost,
            centre,
            weights,
            cfg.center_divide_by_np,
        )
