"""Policies acting from observations: the reference DMPC, its optimisers, exact best responses.

The light modules are imported here (exact best responses and the Nash-gap analysis);
:class:`~uav_formation_env.policies.dmpc.NashDMPCPolicy` is imported on first use
(``from uav_formation_env.policies import NashDMPCPolicy``), so that importing one policy module
does not load the optimisers' compiled kernels.
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
}


def __getattr__(name: str) -> Any:
    """Import the DMPC policy on first use (PEP 562)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "NASH_METHODS",
    "DMPCRecords",
    "NashDMPCPolicy",
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
    "nash_gap",
    "solve_box_qp",
]
