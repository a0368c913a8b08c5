"""Policies acting from observations: the reference DMPC, its optimisers, exact best responses,
the simple policies (random, consensus PD heuristic) and a saved stable-baselines3 model.

Modules: ``dmpc`` (:class:`NashDMPCPolicy`), ``dmpc_step`` (its solvers and step records),
``broadcast`` (what a UAV knows), ``best_response`` and ``nash`` (exact answers, Nash gap),
``optimizers`` (PIO / LFPIO / PSO), ``heuristic`` (the consensus PD law), ``simple``
(:class:`RandomPolicy`, :class:`HeuristicPolicy`), ``learned`` (:class:`SB3Policy`) and
``registry`` (the one list of policy names, :func:`make_policy`).

The light modules are imported here (exact best responses and the Nash-gap analysis); the others
are imported on first use (``from uav_formation_env.policies import NashDMPCPolicy``), so that
importing one policy module does not load the optimisers.
"""

from typing import Any

from uav_formation_env.policies.best_response import (
    BestResponse,
    BoxQPResult,
    ExactConfig,
    best_response,
    box_of,
    identification_evaluations,
    solve_box_qp,
)
from uav_formation_env.policies.nash import (
    NASH_METHODS,
    NashConfig,
    NashGap,
    NashSolution,
    iterated_best_response,
    nash_gap,
)

_LAZY = {
    "NashDMPCPolicy": "uav_formation_env.policies.dmpc",
    "DMPCRecords": "uav_formation_env.policies.dmpc",
    "StepRecord": "uav_formation_env.policies.dmpc",
    "RandomPolicy": "uav_formation_env.policies.simple",
    "HeuristicPolicy": "uav_formation_env.policies.simple",
    "SB3Policy": "uav_formation_env.policies.learned",
    "SB3_ALGORITHMS": "uav_formation_env.policies.learned",
    "BatchPolicy": "uav_formation_env.policies.registry",
    "DMPC_OPTIMIZERS": "uav_formation_env.policies.registry",
    "POLICY_NAMES": "uav_formation_env.policies.registry",
    "make_policy": "uav_formation_env.policies.registry",
}


def __getattr__(name: str) -> Any:
    """Import the DMPC policy, the simple and learned policies and the registry on first use
    (PEP 562)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "DMPC_OPTIMIZERS",
    "NASH_METHODS",
    "POLICY_NAMES",
    "SB3_ALGORITHMS",
    "BatchPolicy",
    "DMPCRecords",
    "HeuristicPolicy",
    "NashDMPCPolicy",
    "RandomPolicy",
    "SB3Policy",
    "StepRecord",
    "BestResponse",
    "BoxQPResult",
    "ExactConfig",
    "NashConfig",
    "NashGap",
    "NashSolution",
    "best_response",
    "box_of",
    "identification_evaluations",
    "iterated_best_response",
    "make_policy",
    "nash_gap",
    "solve_box_qp",
]
