"""Policies acting from observations: the reference DMPC, its optimisers, exact best responses.

Only the light modules are re-exported here (exact best responses and the Nash-gap analysis), so
that importing one policy module does not load the optimisers' compiled kernels; import
:class:`~uav_formation_env.policies.dmpc.NashDMPCPolicy` from its module.
"""

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

__all__ = [
    "NASH_METHODS",
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
