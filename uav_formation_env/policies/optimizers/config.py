"""Optimiser configurations (docs/model.md §6, Table 1), their validation, and the result type."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

FITNESS_EPS = 1e-12  # ε of f = 1/(J + ε), docs/model.md §9b

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
    """Pigeon-inspired optimisation (docs/model.md §6.1; Table 1: Nc1max = 25, Nc2max = 5, R =
    0.1)."""

    n_pigeons: int = 30  # Np [proposed, docs/model.md §6]
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
    """Lévy-flight PIO (docs/model.md §6.2; Table 1: Ncmax = 30, R = 0.1, r1 = 0.01)."""

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
