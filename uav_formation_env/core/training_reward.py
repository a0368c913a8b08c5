"""The training reward ``episode.reward = "train"``: bounded kernels of J_i's and the mission's
terms.

One definition, used by the episode layer (:mod:`uav_formation_env.episode`) and so by every view
and trainer. Each term is a kernel in [0, 1] of a physical error divided by a documented scale
(:class:`~uav_formation_env.config.TrainingRewardConfig`; the table is in docs/training.md); the
reward is their weighted sum, so that it is O(1) per UAV-step and positive, and an episode that
ends early stops earning.

J_i's stage terms arrive already weighted (q, r, n, s of :class:`~uav_formation_env.config.
CostConfig`); dividing by the weight recovers the physical error, so a term whose weight is 0 in
the scenario is a kernel of 1 (nothing to learn from it).
"""

from __future__ import annotations

from typing import Any

from uav_formation_env.config import CostConfig, TrainingRewardConfig
from uav_formation_env.core.array_api import namespace
from uav_formation_env.core.cost import CostTerms

Array = Any  # numpy array or torch tensor

TERMS = ("velocity", "formation", "route", "energy", "separation", "clearance")


def _kernel(squared_error: Array, scale: float) -> Array:
    """1 / (1 + squared_error / scale²) in (0, 1]: 1/2 at one scale, and a gradient far out."""
    return 1.0 / (1.0 + squared_error / (scale * scale))


def _unweighted(term: Array, weight: float) -> Array:
    """A J_i term divided by its weight (0 where the weight is 0: the term is absent)."""
    return term / weight if weight > 0 else term * 0.0


def reward_terms(
    config: TrainingRewardConfig,
    weights: CostConfig,
    cost: CostTerms,
    route_offset: Array,
    obstacle_distance: Array,
    degree: Array,
) -> dict[str, Array]:
    """The weighted kernels of one step, per UAV.

    Args:
        config: the reward's weights and scales.
        weights: J_i's weights (the scenario's ``cost``), to undo them.
        cost: (B, N) J_i's stage terms of the transition.
        route_offset: (B, N) horizontal distance of each UAV from its slot on the preset route [m].
        obstacle_distance: (B, N) distance to the nearest obstacle surface [m] (inf: none).
        degree: (B, N) how many UAVs each one hears (Σ_j h_ij); the formation error is the
            mean over them, so that its scale does not grow with the graph.

    Returns:
        name -> (B, N) weighted kernel, for the names of :data:`TERMS`.
    """
    xp = namespace(route_offset)
    zero = xp.zeros_like(route_offset)
    shortfall = xp.maximum(config.clearance_margin - obstacle_distance, zero)
    errors = {
        "velocity": (_unweighted(cost.velocity, weights.n), config.velocity_scale),
        "formation": (
            _unweighted(cost.formation, weights.q) / xp.maximum(degree, 1.0),
            config.formation_scale,
        ),
        "route": (route_offset * route_offset, config.route_scale),
        "energy": (_unweighted(cost.energy, weights.r), config.energy_scale),
        "separation": (_unweighted(cost.separation, weights.separation), config.separation_scale),
        "clearance": (shortfall * shortfall, config.clearance_scale),
    }
    return {
        name: getattr(config, name) * _kernel(error, scale)
        for name, (error, scale) in errors.items()
    }


def training_reward(terms: dict[str, Array], terminated: Array, penalty: float) -> Array:
    """(B, N) the sum of the terms, minus ``penalty`` for every agent of a terminated copy.

    Args:
        terms: name -> (B, N) weighted kernels (:func:`reward_terms`).
        terminated: (B,) bool, copies that terminate in this step.
        penalty: the termination penalty [-].
    """
    total = sum(terms.values())
    xp = namespace(total)
    return total - penalty * xp.astype(terminated[:, None], total.dtype)
