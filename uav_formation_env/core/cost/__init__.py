"""The game cost J_i (eq. 6, docs/model.md §4): one definition behind the env reward and the MPC
objective.

For UAV i over a horizon of H steps, with ``ε_ij(k) = (z_i(k) - z^d_i) - (ẑ_j(k) - z^d_j)``:

    J_i = q Σ_j h_ij Σ_{k<H} ||ε_ij(k)||² + r Σ_{k<H} ||u_i(k)||²
        + m Σ_j h_ij ||ε_ij(H)||² + n Σ_{k<=H} ||v_i(k) - v^d_i(k)||²
        + s Σ_{j≠i} Σ_{k<=H} max(0, d_s - ||p_i(k) - p̂_j(k)||)²
        + o Σ_obstacles Σ_{k<=H+L} max(0, R + c_o - D_i(k))²

``||x||_w`` is read as ``w xᵀx`` (docs/model.md §4.1). The last two lines are not in the paper.
The separation term (docs/deviations.md §5) runs over every other UAV j (sensed, not only
neighbours) and vanishes while all UAVs are at least d_s apart. The obstacle term
(docs/deviations.md §8) runs over the obstacles UAV i senses, with D_i the horizontal distance
from an obstacle's centre and R its radius, and vanishes outside every clearance circle R + c_o;
its points k = H+1..H+L are the free continuation ``p_i(H) + (k - H) δ v_i(H)`` of the terminal
state (L = ``cost.obstacle_lookahead``). ``s = 0`` and ``o = 0`` give the paper's J_i. The stage
cost, the reward of one realised transition, is the ``k``-th summand: ``q Σ_j h_ij ||ε_ij||² +
r ||u_i||² + n ||v_i - v^d_i||² + s Σ_{j≠i} max(0, d_s - ||p_i - p_j||)² + o Σ_obstacles
max(0, R + c_o - D_i)²``. Both are built from the same term functions below.

Shapes: B scenario copies, N UAVs, P candidates per UAV, H horizon steps.

Neighbour predictions come either as one trajectory per sender, seen alike by every receiver
(B, N, H+1, 6), or as each receiver's own view of every sender (B, N_recv, N_send, H+1, 6): a UAV
that only knows relative states works in its own frame, and the views of a sender differ between
receivers by a translation (and by sensing noise). The formula is the same; only the sum over the
senders runs over the receiver's own views. :func:`prepare_horizon_cost` computes the part of J_i
that does not depend on the candidates once, for optimisers that evaluate many populations.
"""

from uav_formation_env.core.cost.horizon import (
    HorizonCost,
    horizon_cost,
    lookahead_times,
    prepare_horizon_cost,
    prepare_slot_horizon_cost,
)
from uav_formation_env.core.cost.quadratic import (
    ClearanceCost,
    QuadraticCost,
    input_response,
    polarisation_points,
    state_response,
    superposed_rollout,
)
from uav_formation_env.core.cost.stage import (
    CostTerms,
    NeighbourMoments,
    anchored,
    formation_error_sq,
    neighbour_moments,
    obstacle_active,
    obstacle_sq,
    others_mask,
    separation_active,
    separation_sq,
    stage_cost,
    take_flat,
    velocity_error_sq,
)

__all__ = [
    "ClearanceCost",
    "CostTerms",
    "HorizonCost",
    "NeighbourMoments",
    "QuadraticCost",
    "anchored",
    "formation_error_sq",
    "horizon_cost",
    "input_response",
    "lookahead_times",
    "neighbour_moments",
    "obstacle_active",
    "obstacle_sq",
    "others_mask",
    "polarisation_points",
    "prepare_horizon_cost",
    "prepare_slot_horizon_cost",
    "separation_active",
    "separation_sq",
    "stage_cost",
    "state_response",
    "superposed_rollout",
    "take_flat",
    "velocity_error_sq",
]
