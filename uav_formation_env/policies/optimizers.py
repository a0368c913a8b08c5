"""Batched derivative-free minimisers: PIO, LFPIO (SPEC §6) and a PSO baseline.

The optimisers know nothing about UAVs. They minimise a vectorised cost over a box, for a batch of
independent problems at once, in the evosax / pymoo style: the whole population of every problem
is evaluated in one call, the update rules are array operations, and all randomness comes from the
``numpy.random.Generator`` handed in (same seed, bit-identical result).

Shapes: a problem is a point of shape ``dims`` (``(H, 3)`` for a UAV's input sequence); a call
solves ``batch`` problems (``(M,)`` for M UAVs), so ``x0`` has shape ``(*batch, *dims)`` and the
cost is called on populations ``(*batch, P, *dims)`` returning ``(*batch, P)``. Internally ``dims``
is flattened to ``n`` components.

Conventions shared by all three methods (SPEC §6):

- Costs are assumed to be ``J >= 0`` (the paper's performance index is a sum of squares). Fitness
  is ``f = 1 / (max(J, 0) + 1e-12)``; it only weights the LFPIO/PIO centre and orders the PIO
  landmark survivors. NaN costs are treated as ``+inf`` (fitness 0, never selected as best).
- Pigeon/particle 0 is the warm start ``x0`` (clipped into the box, a no-op for a feasible warm
  start); the others are uniform in the box; initial velocities are 0.
- Positions are clipped to ``[low, high]`` after every move; velocities are kept as they are.
- The best position ever evaluated is updated after every evaluation batch and returned, so the
  result is never worse than ``x0`` and ``cost_fn(result.x)`` reproduces ``result.cost``.
- ``rand`` is one U[0, 1) scalar per pigeon per iteration, or one per component with
  ``per_dimension_rand``.

Speed: at the DMPC's sizes (a few problems of 30 pigeons x 15 components) an iteration is
dominated by per-call overhead, so the loops work in preallocated buffers, with in-place ufuncs and
plain indexing. LFPIO's per-iteration bookkeeping (moves, clipping, best-so-far, greedy choice,
weighted centre) also exists as two numba kernels that repeat the numpy operations per component
in the same order, so they give the same numbers bit for bit (tested); they are used when numba is
installed (the ``[fast]`` extra) unless ``UAV_FORMATION_NO_NUMBA`` is set. What is left is mostly
the Gaussian draws of the Lévy steps (``Generator.standard_normal``, kept so that a seed gives the
same stream as before).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from uav_formation_env.policies.levy import (
    TINY,
    levy_denominator_into,
    levy_steps,
    levy_steps_into,
    mantegna_components,
    mantegna_sigma,
)

try:  # pragma: no cover - exercised when the [fast] extra is installed
    if os.environ.get("UAV_FORMATION_NO_NUMBA"):
        raise ImportError("disabled by UAV_FORMATION_NO_NUMBA")
    import numba
except ImportError:  # pragma: no cover
    numba = None

COMPILED_AVAILABLE = numba is not None  # LFPIO's bookkeeping can run as compiled kernels

__all__ = [
    "COMPILED_AVAILABLE",
    "FITNESS_EPS",
    "OPTIMIZERS",
    "LFPIOConfig",
    "OptimResult",
    "PIOConfig",
    "PSOConfig",
    "fitness",
    "levy_steps",
    "mantegna_components",
    "mantegna_sigma",
    "minimise",
    "n_evaluations",
    "weighted_centre",
]

FITNESS_EPS = 1e-12  # ε of f = 1/(J + ε), SPEC §9b

CostFn = Callable[[np.ndarray], np.ndarray]


def _require(condition: bool, field_name: str, rule: str) -> None:
    if not condition:
        raise ValueError(f"invalid optimiser field '{field_name}': {rule}")


def _int_at_least(value: object, field_name: str, minimum: int) -> None:
    is_int = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    _require(is_int, field_name, f"must be an int, got {value!r}")
    _require(value >= minimum, field_name, f"must be >= {minimum}, got {value!r}")


def _real_at_least(value: object, field_name: str, minimum: float = 0.0) -> None:
    is_real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, bool
    )
    _require(is_real and math.isfinite(value), field_name, f"must be finite, got {value!r}")
    _require(value >= minimum, field_name, f"must be >= {minimum}, got {value!r}")


def _flag(value: object, field_name: str) -> None:
    _require(isinstance(value, bool), field_name, f"must be a bool, got {value!r}")


@dataclass(frozen=True)
class PIOConfig:
    """Pigeon-inspired optimisation (SPEC §6.1; Table 1: Nc1max = 25, Nc2max = 5, R = 0.1)."""

    n_pigeons: int = 30  # Np [proposed, SPEC §6]
    map_compass_iters: int = 25  # Nc1max
    landmark_iters: int = 5  # Nc2max; survivors halve each iteration, ceil(Np/2)
    map_compass_factor: float = 0.1  # R in V e^{-R l}
    per_dimension_rand: bool = False  # rand per component instead of per pigeon
    center_divide_by_np: bool = False  # literal eq. 17: centre = Σ f X / (Np Σ f)

    def __post_init__(self) -> None:
        _int_at_least(self.n_pigeons, "n_pigeons", 1)
        _int_at_least(self.map_compass_iters, "map_compass_iters", 0)
        _int_at_least(self.landmark_iters, "landmark_iters", 0)
        _real_at_least(self.map_compass_factor, "map_compass_factor")
        _flag(self.per_dimension_rand, "per_dimension_rand")
        _flag(self.center_divide_by_np, "center_divide_by_np")


@dataclass(frozen=True)
class LFPIOConfig:
    """Lévy-flight PIO (SPEC §6.2; Table 1: Ncmax = 30, R = 0.1, r1 = 0.01)."""

    n_pigeons: int = 30  # Np, no halving in LFPIO
    iters: int = 30  # Ncmax
    map_compass_factor: float = 0.1  # R
    levy_scale: float = 0.01  # r1
    levy_beta: float = 1.5  # β of the Mantegna step (the paper's second δ)
    per_dimension_rand: bool = False
    center_divide_by_np: bool = False  # literal eq. 18: centre divided by Np Σ f

    def __post_init__(self) -> None:
        _int_at_least(self.n_pigeons, "n_pigeons", 1)
        _int_at_least(self.iters, "iters", 0)
        _real_at_least(self.map_compass_factor, "map_compass_factor")
        _real_at_least(self.levy_scale, "levy_scale")
        _real_at_least(self.levy_beta, "levy_beta")
        _require(0 < self.levy_beta < 2, "levy_beta", f"must be in (0, 2), got {self.levy_beta}")
        _flag(self.per_dimension_rand, "per_dimension_rand")
        _flag(self.center_divide_by_np, "center_divide_by_np")


@dataclass(frozen=True)
class PSOConfig:
    """Global-best particle swarm, the comparison baseline.

    Constriction coefficients of Clerc & Kennedy (2002): inertia 0.7298, c1 = c2 = 1.49618, with
    per-component random factors as in standard PSO.
    """

    n_particles: int = 30
    iters: int | None = None  # None: match LFPIO's default budget (1830 evaluations), see resolved
    inertia: float = 0.7298
    cognitive: float = 1.49618  # c1, pull towards the particle's own best
    social: float = 1.49618  # c2, pull towards the swarm's best
    per_dimension_rand: bool = True

    def __post_init__(self) -> None:
        _int_at_least(self.n_particles, "n_particles", 1)
        if self.iters is not None:
            _int_at_least(self.iters, "iters", 0)
        _real_at_least(self.inertia, "inertia", -math.inf)
        _real_at_least(self.cognitive, "cognitive")
        _real_at_least(self.social, "social")
        _flag(self.per_dimension_rand, "per_dimension_rand")

    @property
    def resolved_iters(self) -> int:
        """Iterations run: ``iters``, or the count whose budget is closest to LFPIO's default."""
        if self.iters is not None:
            return self.iters
        budget = n_evaluations(LFPIOConfig())
        return max(0, round((budget - self.n_particles) / self.n_particles))


OptimConfig = PIOConfig | LFPIOConfig | PSOConfig
OPTIMIZERS: dict[str, type[PIOConfig] | type[LFPIOConfig] | type[PSOConfig]] = {
    "pio": PIOConfig,
    "lfpio": LFPIOConfig,
    "pso": PSOConfig,
}


def n_evaluations(config: OptimConfig) -> int:
    """Cost evaluations per problem that :func:`minimise` spends with ``config``.

    PIO: ``Np (1 + Nc1max) + Σ_l Np(l)`` (810 by default); LFPIO: ``Np (1 + 2 Ncmax)`` (1830);
    PSO: ``P (1 + iters)`` (1830 by default).
    """
    if isinstance(config, PIOConfig):
        alive, landmark = config.n_pigeons, 0
        for _ in range(config.landmark_iters):
            alive = math.ceil(alive / 2)
            landmark += alive
        return config.n_pigeons * (1 + config.map_compass_iters) + landmark
    if isinstance(config, LFPIOConfig):
        return config.n_pigeons * (1 + 2 * config.iters)
    if isinstance(config, PSOConfig):
        return config.n_particles * (1 + config.resolved_iters)
    raise TypeError(f"unknown optimiser config {type(config).__name__}")


@dataclass
class OptimResult:
    """Outcome of :func:`minimise`.

    Attributes:
        x: ``(*batch, *dims)`` best position evaluated, inside ``[low, high]``.
        cost: ``(*batch,)`` its cost (``<= initial_cost``).
        initial_cost: ``(*batch,)`` cost of the (clipped) warm start ``x0``.
        n_evals: Cost evaluations spent per problem (each batch element).
    """

    x: np.ndarray
    cost: np.ndarray
    initial_cost: np.ndarray
    n_evals: int


def fitness(cost: np.ndarray) -> np.ndarray:
    """Fitness ``f = 1 / (max(J, 0) + 1e-12)``; ``+inf`` cost gives 0 (SPEC §6)."""
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
    centre = _weighted_centre(flat_x, cost.reshape(flat_x.shape[:2]), divide_by_count)
    return centre.reshape(*batch, x.shape[-1])


def _weighted_centre(
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


class _Run:
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


def _pio(run: _Run, rng: np.random.Generator, cfg: PIOConfig) -> None:
    x = run.initial_population(rng, cfg.n_pigeons)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    pull = np.empty_like(x)
    # Map-and-compass stage (eq. 16): decaying velocity plus a pull towards the global best.
    for it in range(1, cfg.map_compass_iters + 1):
        rand = run.rand(rng, cfg.n_pigeons, cfg.per_dimension_rand)
        np.subtract(run.best_x[:, None, :], x, out=pull)
        np.multiply(rand, pull, out=pull)
        np.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        np.add(v, pull, out=v)
        np.add(x, v, out=x)
        run.clip(x, out=x)
        cost = run.evaluate(x)
    # Landmark stage (eq. 17): keep the better half (ceil), move towards their weighted centre.
    # The survivor count is the same for every problem, so this is a per-problem sort + slice.
    alive = cfg.n_pigeons
    for _ in range(cfg.landmark_iters):
        alive = math.ceil(alive / 2)
        keep = np.argsort(cost, axis=-1, kind="stable")[:, :alive]
        rows = run.rows[:, None]
        x, cost = x[rows, keep], cost[rows, keep]
        centre = _weighted_centre(x, cost, cfg.center_divide_by_np)[:, None, :]
        step = run.rand(rng, alive, cfg.per_dimension_rand) * (centre - x)
        x = run.clip(np.add(x, step, out=step), out=step)
        cost = run.evaluate(x)


def _lfpio_numpy(run: _Run, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    """LFPIO with preallocated contiguous buffers: the same operations, in the same order, as
    eq. 18 (so the same numbers as a plain array-expression version, bit for bit).

    Y1 overwrites X in place once ``X^c - X`` and ``X_g - X`` are formed; both candidates are
    copied into one population for a single cost call; the greedy choice copies the winning Y2
    rows over Y1 (= X_l) and takes the elementwise minimum of the two costs (``where(c2 < c1,
    c2, c1)`` and ``minimum(c1, c2)`` are the same numbers once NaN is mapped to +inf).
    """
    p = cfg.n_pigeons
    x = run.initial_population(rng, p)  # X_l, updated in place (Y1 is written over it)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    y2, to_best, to_centre, work = (np.empty_like(x) for _ in range(4))
    levy = np.empty((2, *x.shape))
    both = np.empty((run.nb, 2 * p, run.n))
    low, high = run.full_bounds(p)
    centre = _weighted_centre(x, cost, cfg.center_divide_by_np, work)[:, None, :]
    for it in range(1, cfg.iters + 1):
        # eq. 18 with SPEC's resolutions: X_{l-1} in the velocity, X^c_{l-1} in the Lévy move.
        rand = run.rand(rng, p, cfg.per_dimension_rand)
        np.subtract(centre, x, out=to_centre)
        np.subtract(run.best_x[:, None, :], x, out=to_best)
        np.multiply(rand, to_best, out=to_best)
        np.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        np.add(v, to_best, out=v)
        y1 = np.add(x, v, out=x)  # Y1 = clip(X + V), written over X
        np.minimum(np.maximum(y1, low, out=y1), high, out=y1)
        s = levy_steps_into(rng, levy, cfg.levy_beta)
        np.multiply(cfg.levy_scale, s, out=s)
        np.multiply(s, to_centre, out=s)
        np.add(y1, s, out=y2)  # Y2 = clip(Y1 + r1 s ⊙ (X^c - X))
        np.minimum(np.maximum(y2, low, out=y2), high, out=y2)
        # Both candidates in one cost call (population 2P); then greedy between Y1 and Y2 only.
        np.concatenate((y1, y2), axis=1, out=both)
        both_cost = run.evaluate(both)
        cost = both_cost[:, :p]
        take_y2 = both_cost[:, p:] < cost
        np.copyto(x, y2, where=take_y2[..., None])
        np.minimum(cost, both_cost[:, p:], out=cost)
        centre = _weighted_centre(x, cost, cfg.center_divide_by_np, work)[:, None, :]


def _lfpio_move(
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
    """One LFPIO move (eq. 18) in place, the operations of :func:`_lfpio_numpy` per component.

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


def _lfpio_select(
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
    """After the cost call: best-so-far update, greedy Y1/Y2 choice and the new weighted centre,
    in place; the operations of ``_Run.evaluate`` and :func:`_weighted_centre` per problem.

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
    _pairwise_sum = numba.njit(cache=True)(_pairwise_sum)
    _lfpio_move_compiled = numba.njit(cache=True)(_lfpio_move)
    _lfpio_select_compiled = numba.njit(cache=True)(_lfpio_select)


def _lfpio_compiled(run: _Run, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    """:func:`_lfpio_numpy` with the per-iteration bookkeeping in two compiled kernels.

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
    centre = np.ascontiguousarray(_weighted_centre(x, cost, cfg.center_divide_by_np))
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


def _pso(run: _Run, rng: np.random.Generator, cfg: PSOConfig) -> None:
    p = cfg.n_particles
    x = run.initial_population(rng, p)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    own_x, own_cost = x.copy(), cost
    for _ in range(cfg.resolved_iters):
        r1 = run.rand(rng, p, cfg.per_dimension_rand)
        r2 = run.rand(rng, p, cfg.per_dimension_rand)
        v = (
            cfg.inertia * v
            + cfg.cognitive * r1 * (own_x - x)
            + cfg.social * r2 * (run.best_x[:, None, :] - x)
        )
        x = run.clip(x + v)
        cost = run.evaluate(x)
        improved = cost < own_cost
        np.copyto(own_x, x, where=improved[..., None])
        own_cost = np.where(improved, cost, own_cost)


def minimise(
    cost_fn: CostFn,
    x0: np.ndarray,
    low: np.ndarray | float,
    high: np.ndarray | float,
    rng: np.random.Generator,
    config: OptimConfig,
    *,
    batch_ndim: int = 1,
    compiled: bool | None = None,
) -> OptimResult:
    """Minimise a vectorised cost over a box for a batch of independent problems.

    Args:
        cost_fn: Maps positions ``(*batch, P, *dims)`` to costs ``(*batch, P)``, assumed ``>= 0``.
            Called once per evaluation batch on the whole population; ``P`` varies between calls
            (PIO's landmark stage shrinks it, LFPIO evaluates ``2 Np`` candidates at once). It
            must not modify its argument, and must copy it to keep it: the array may be a
            buffer that later iterations overwrite.
        x0: ``(*batch, *dims)`` warm start; it is pigeon 0 and the initial global best.
        low: Lower bounds, broadcastable to ``(*batch, *dims)``, finite.
        high: Upper bounds, broadcastable to ``(*batch, *dims)``, finite, ``>= low``.
        rng: The only source of randomness.
        config: :class:`PIOConfig`, :class:`LFPIOConfig` or :class:`PSOConfig`.
        batch_ndim: How many leading axes of ``x0`` are batch axes (1 for ``(M, H, 3)``).
        compiled: Run LFPIO's per-iteration bookkeeping as compiled numba kernels (the same
            numbers as the numpy code, ~2x faster at small batches). None: whenever numba is
            installed (the ``[fast]`` extra) and ``UAV_FORMATION_NO_NUMBA`` is unset. Only LFPIO
            with ``prod(dims) >= 2`` has kernels; other cases always use numpy.

    Returns:
        The best position evaluated per problem, never worse than ``x0``; see :class:`OptimResult`.

    Raises:
        TypeError: If ``rng`` is not a ``numpy.random.Generator`` or ``config`` is unknown.
        ValueError: On bad bounds, ``batch_ndim`` or a cost of the wrong shape.
    """
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    run = _Run(cost_fn, x0, low, high, batch_ndim)
    if isinstance(config, PIOConfig):
        _pio(run, rng, config)
    elif isinstance(config, LFPIOConfig):
        if compiled is None:
            compiled = COMPILED_AVAILABLE
        if compiled and not COMPILED_AVAILABLE:
            raise RuntimeError("compiled=True needs numba (the [fast] extra)")
        if compiled and run.n >= 2:
            _lfpio_compiled(run, rng, config)
        else:
            _lfpio_numpy(run, rng, config)
    elif isinstance(config, PSOConfig):
        _pso(run, rng, config)
    else:
        raise TypeError(f"unknown optimiser config {type(config).__name__}")
    return run.result()
