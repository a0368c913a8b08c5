"""The reference DMPC's solvers by name: their configs, and :func:`solver_config`.

Kept apart from :mod:`~uav_formation_env.policies.registry` so that the DMPC policy and its
step solvers can name their solvers without importing the registry, which builds them (no
import circle).
"""

from __future__ import annotations

from uav_formation_env.policies.best_response import ExactConfig
from uav_formation_env.policies.nash import NashConfig
from uav_formation_env.policies.optimizers.config import (
    OPTIMIZERS,
    LFPIOConfig,
    PIOConfig,
    PSOConfig,
)

__all__ = ["DMPC_OPTIMIZERS", "DMPC_SOLVERS", "SolverConfig", "solver_config"]

SolverConfig = PIOConfig | LFPIOConfig | PSOConfig | ExactConfig | NashConfig
# name -> the config of NashDMPCPolicy's solver (its defaults)
DMPC_SOLVERS: dict[str, type[SolverConfig]] = {
    **OPTIMIZERS,
    "exact": ExactConfig,
    "nash": NashConfig,
}
DMPC_OPTIMIZERS = tuple(DMPC_SOLVERS)  # ("pio", "lfpio", "pso", "exact", "nash")


def solver_config(optimizer: str | SolverConfig) -> SolverConfig:
    """The solver config of a DMPC solver name (case-insensitive; its defaults), or the config
    itself."""
    if isinstance(optimizer, SolverConfig):
        return optimizer
    if isinstance(optimizer, str) and optimizer.lower() in DMPC_SOLVERS:
        return DMPC_SOLVERS[optimizer.lower()]()
    raise ValueError(
        f"unknown optimizer {optimizer!r}: expected one of {sorted(DMPC_SOLVERS)} or a config "
        "object"
    )
