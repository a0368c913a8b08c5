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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from uav_formation_env.policies.levy import (
    levy_steps,
    mantegna_components,
    mantegna_sigma,
)

__all__ = [
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
    f = fitness(cost)
    # Normalise by the largest fitness first: f can reach 1e12 (J = 0) and the ratio is unchanged.
    f_max = f.max(axis=-1, keepdims=True)
    w = np.divide(f, f_max, out=np.ones_like(f), where=f_max > 0)
    centre = (w[..., None] * x).sum(axis=-2) / w.sum(axis=-1)[..., None]
    return centre / x.shape[-2] if divide_by_count else centre


class _Run:
    """Flattening, clipping, counting and best-so-far bookkeeping for one :func:`minimise` call."""

    def __init__(self, cost_fn: CostFn, x0: np.ndarray, low, high, batch_ndim: int) -> None:
        x0 = np.asarray(x0, dtype=np.float64)
        if not 0 <= batch_ndim <= x0.ndim:
            raise ValueError(f"batch_ndim must be in [0, {x0.ndim}], got {batch_ndim}")
        self.batch, self.dims = x0.shape[:batch_ndim], x0.shape[batch_ndim:]
        n = math.prod(self.dims)
        lo = np.broadcast_to(np.asarray(low, dtype=np.float64), x0.shape)
        hi = np.broadcast_to(np.asarray(high, dtype=np.float64), x0.shape)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            raise ValueError("low and high must be finite with low <= high")
        # (*batch, 1, n): broadcasts against populations (*batch, P, n).
        self.low = lo.reshape(*self.batch, 1, n)
        self.high = hi.reshape(*self.batch, 1, n)
        self.x0 = self.clip(x0.reshape(*self.batch, 1, n))
        self.cost_fn = cost_fn
        self.n_evals = 0
        self.best_x = self.x0[..., 0, :]
        self.best_cost = np.full(self.batch, np.inf)
        self.initial_cost: np.ndarray | None = None

    def clip(self, x: np.ndarray) -> np.ndarray:
        return np.clip(x, self.low, self.high)

    def rand(self, rng: np.random.Generator, size: int, per_dim: bool) -> np.ndarray:
        """U[0, 1) factors ``(*batch, size, n or 1)``: per component or one per pigeon."""
        return rng.random((*self.batch, size, self.low.shape[-1] if per_dim else 1))

    def initial_population(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """``(*batch, size, n)``: the warm start, then uniform samples in the box."""
        u = rng.random((*self.batch, size - 1, self.low.shape[-1]))
        uniform = self.clip(self.low + (self.high - self.low) * u)
        return np.concatenate([self.x0, uniform], axis=-2)

    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """Cost ``(*batch, K)`` of ``x`` ``(*batch, K, n)`` in one call; updates the best."""
        size = x.shape[-2]
        cost = np.asarray(self.cost_fn(x.reshape(*self.batch, size, *self.dims)), dtype=np.float64)
        if cost.shape != (*self.batch, size):
            raise ValueError(f"cost_fn returned shape {cost.shape}, expected {(*self.batch, size)}")
        cost = np.where(np.isnan(cost), np.inf, cost)  # NaN can never become the best
        self.n_evals += size
        if self.initial_cost is None:  # the first batch is the initial population, x0 first
            self.initial_cost = cost[..., 0].copy()
        i = np.argmin(cost, axis=-1)[..., None]
        cand_cost = np.take_along_axis(cost, i, axis=-1)[..., 0]
        cand_x = np.take_along_axis(x, i[..., None], axis=-2)[..., 0, :]
        # Strict '<': on ties the older point (ultimately x0, the initial best_x) is kept.
        better = cand_cost < self.best_cost
        self.best_x = np.where(better[..., None], cand_x, self.best_x)
        self.best_cost = np.where(better, cand_cost, self.best_cost)
        return cost

    def result(self) -> OptimResult:
        assert self.initial_cost is not None, "the initial population is always evaluated"
        return OptimResult(
            x=self.best_x.reshape(*self.batch, *self.dims),
            cost=self.best_cost,
            initial_cost=self.initial_cost,
            n_evals=self.n_evals,
        )


def _pio(run: _Run, rng: np.random.Generator, cfg: PIOConfig) -> None:
    x = run.initial_population(rng, cfg.n_pigeons)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    # Map-and-compass stage (eq. 16): decaying velocity plus a pull towards the global best.
    for it in range(1, cfg.map_compass_iters + 1):
        rand = run.rand(rng, cfg.n_pigeons, cfg.per_dimension_rand)
        v = v * math.exp(-cfg.map_compass_factor * it) + rand * (run.best_x[..., None, :] - x)
        x = run.clip(x + v)
        cost = run.evaluate(x)
    # Landmark stage (eq. 17): keep the better half (ceil), move towards their weighted centre.
    # The survivor count is the same for every problem, so this is a per-problem sort + slice.
    alive = cfg.n_pigeons
    for _ in range(cfg.landmark_iters):
        alive = math.ceil(alive / 2)
        keep = np.argsort(cost, axis=-1, kind="stable")[..., :alive]
        x = np.take_along_axis(x, keep[..., None], axis=-2)
        cost = np.take_along_axis(cost, keep, axis=-1)
        centre = weighted_centre(x, cost, cfg.center_divide_by_np)[..., None, :]
        x = run.clip(x + run.rand(rng, alive, cfg.per_dimension_rand) * (centre - x))
        cost = run.evaluate(x)


def _lfpio(run: _Run, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    p = cfg.n_pigeons
    x = run.initial_population(rng, p)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    centre = weighted_centre(x, cost, cfg.center_divide_by_np)[..., None, :]
    for it in range(1, cfg.iters + 1):
        # eq. 18 with SPEC's resolutions: X_{l-1} in the velocity, X^c_{l-1} in the Lévy move.
        rand = run.rand(rng, p, cfg.per_dimension_rand)
        v = v * math.exp(-cfg.map_compass_factor * it) + rand * (run.best_x[..., None, :] - x)
        y1 = run.clip(x + v)
        s = levy_steps(rng, x.shape, cfg.levy_beta)
        y2 = run.clip(y1 + cfg.levy_scale * s * (centre - x))
        # Both candidates in one cost call (population 2P); then greedy between Y1 and Y2 only.
        both = run.evaluate(np.concatenate([y1, y2], axis=-2))
        take_y2 = both[..., p:] < both[..., :p]
        x = np.where(take_y2[..., None], y2, y1)
        cost = np.where(take_y2, both[..., p:], both[..., :p])
        centre = weighted_centre(x, cost, cfg.center_divide_by_np)[..., None, :]


def _pso(run: _Run, rng: np.random.Generator, cfg: PSOConfig) -> None:
    p = cfg.n_particles
    x = run.initial_population(rng, p)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    own_x, own_cost = x, cost
    for _ in range(cfg.resolved_iters):
        r1 = run.rand(rng, p, cfg.per_dimension_rand)
        r2 = run.rand(rng, p, cfg.per_dimension_rand)
        v = (
            cfg.inertia * v
            + cfg.cognitive * r1 * (own_x - x)
            + cfg.social * r2 * (run.best_x[..., None, :] - x)
        )
        x = run.clip(x + v)
        cost = run.evaluate(x)
        improved = cost < own_cost
        own_x = np.where(improved[..., None], x, own_x)
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
) -> OptimResult:
    """Minimise a vectorised cost over a box for a batch of independent problems.

    Args:
        cost_fn: Maps positions ``(*batch, P, *dims)`` to costs ``(*batch, P)``, assumed ``>= 0``.
            Called once per evaluation batch on the whole population; ``P`` varies between calls
            (PIO's landmark stage shrinks it, LFPIO evaluates ``2 Np`` candidates at once). It
            must not modify its argument.
        x0: ``(*batch, *dims)`` warm start; it is pigeon 0 and the initial global best.
        low: Lower bounds, broadcastable to ``(*batch, *dims)``, finite.
        high: Upper bounds, broadcastable to ``(*batch, *dims)``, finite, ``>= low``.
        rng: The only source of randomness.
        config: :class:`PIOConfig`, :class:`LFPIOConfig` or :class:`PSOConfig`.
        batch_ndim: How many leading axes of ``x0`` are batch axes (1 for ``(M, H, 3)``).

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
        _lfpio(run, rng, config)
    elif isinstance(config, PSOConfig):
        _pso(run, rng, config)
    else:
        raise TypeError(f"unknown optimiser config {type(config).__name__}")
    return run.result()
