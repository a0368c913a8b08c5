"""A safety shield around any policy: the least change to its actions that keeps every UAV out
of the obstacles it senses and away from the UAVs in its observation slots.

:class:`SafetyShield` is a safety filter between the policy and the plant (as safe-control-gym's
CBF filter), reading only UAV i's local observation, so it is as decentralised as the policy it
wraps; its results are the policy's *and* the shield's.

**Barriers** (second-order control barrier functions of the double integrator, exponential
class-K terms with one gain α [1/s]): for a barrier h(p) >= 0 with ``ḣ = ∇h · v``,

    ḧ + 2 α ḣ + α² h >= 0

keeps h >= 0 wherever it holds from a safe start and the input can meet it. With the
disturbance cancelled by the observer the acceleration is the formation input u_n, so each
barrier is one half-space ``g · u_n >= β`` per UAV:

- obstacle q (vertical cylinder, horizontal distance ρ to its centre, radius r):
  ``h = ρ - r - obstacle_margin``, ``g = (p - c) / ρ`` (horizontal),
  ``β = -v_t² / ρ - 2 α ḣ - α² h`` with ``v_t`` the horizontal speed across g;
- the UAV j in slot s (distance ρ, relative state from :func:`~uav_formation_env.core.
  local_observation.slot_frame`): ``h = ρ - (collision.uav_distance + separation_margin)``,
  ``g = (p_i - p_j) / ρ``; the bound is on the relative acceleration beyond the policy's own
  (which moves a formation as a whole), and UAV i makes half of that correction (j, seeing i,
  the other half; the usual decentralised split).

**Projection**: actions that meet every barrier pass unchanged; elsewhere the least-squares
change inside the box ``|u_n| <= u_max - |estimate|`` (exact active sets of at most three
constraints, tested against scipy's SLSQP; a dual ascent compromise where none is feasible).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import (
    DecodedLocalObservation,
    decode_local_observations,
    slot_frame,
)
from uav_formation_env.policies.broadcast import input_half_width
from uav_formation_env.policies.protocol import PolicyBase, as_batch_policy

__all__ = ["SafetyShield", "ShieldConfig", "barrier_halfspaces", "project_onto_halfspaces"]

# a tiny distance that keeps the barriers' normals finite at the centre of an obstacle [m]
_MIN_DISTANCE = 1e-6
# the bound of an absent slot's half-space: never binding [m/s^2]
_NEVER = -1e9
# violations smaller than this are rounding, not a need to act [-] (normalised action)
_TOLERANCE = 1e-9


def _check_number(value: Any, name: str, positive: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ValueError(f"shield.{name} must be a finite number, got {value!r}")
    if (value <= 0) if positive else (value < 0):
        raise ValueError(f"shield.{name} must be {'> 0' if positive else '>= 0'}, got {value!r}")


@dataclass(frozen=True)
class ShieldConfig:
    """The shield's margins and gain.

    Attributes:
        obstacle_margin: clearance kept from every obstacle's surface [m].
        separation_margin: distance kept beyond ``collision.uav_distance`` between UAVs [m].
        gain: α of the barriers' class-K terms [1/s]; smaller starts avoiding earlier.
        iterations: dual ascent iterations of a projection whose barriers cannot all be met.
    """

    # chosen on validation scenes of random_fields (never the held-out seeds); the sweep of
    # gains and margins is in docs/shield.md, "Settings"
    obstacle_margin: float = 5.0
    separation_margin: float = 3.0
    gain: float = 0.8
    iterations: int = 100

    def __post_init__(self) -> None:
        _check_number(self.obstacle_margin, "obstacle_margin", positive=False)
        _check_number(self.separation_margin, "separation_margin", positive=False)
        _check_number(self.gain, "gain", positive=True)
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int):
            raise ValueError(f"shield.iterations must be an integer, got {self.iterations!r}")
        if self.iterations < 1:
            raise ValueError(f"shield.iterations must be >= 1, got {self.iterations!r}")


def _normal_terms(
    offset: np.ndarray, rate: np.ndarray, clearance: np.ndarray, gain: float
) -> tuple[np.ndarray, np.ndarray]:
    """Unit normal and bound of the barrier ``h = |offset| - clearance``.

    Args:
        offset: (..., 3) position of the UAV relative to what it keeps away from [m].
        rate: (..., 3) rate of ``offset`` [m/s].
        clearance: (...) distance to keep [m].
        gain: α [1/s].

    Returns:
        ``(normal, bound)``: (..., 3) unit normal, (...) bound on ``normal · acceleration``
        [m/s^2] (the barrier condition ``ḧ + 2α ḣ + α² h >= 0``).
    """
    distance = np.maximum(np.linalg.norm(offset, axis=-1), _MIN_DISTANCE)
    normal = offset / distance[..., None]
    h = distance - clearance
    h_dot = np.einsum("...c,...c->...", normal, rate)
    across = np.maximum(np.einsum("...c,...c->...", rate, rate) - h_dot**2, 0.0)
    bound = -across / distance - 2.0 * gain * h_dot - gain**2 * h
    return normal, bound


def barrier_halfspaces(
    decoded: DecodedLocalObservation,
    actions: np.ndarray,
    u_max: float,
    uav_distance: float,
    config: ShieldConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """Every UAV's barrier half-spaces ``normal · u_n >= bound``, one per obstacle slot and one
    per UAV slot of its local observation.

    Args:
        decoded: (B, N, ...) decoded local observations.
        actions: (B, N, 3) the policy's normalised actions, as the plant will apply them (the
            UAV rows bound the change from them) [-].
        u_max: per-axis actuator bound [m/s^2].
        uav_distance: two UAVs closer than this collide [m].
        config: margins and gain.

    Returns:
        ``(normal, bound)``: (B, N, m + S, 3) unit normals (0 for absent slots) and (B, N, m + S)
        bounds [m/s^2] (:data:`_NEVER` for absent slots): obstacles first, then UAV slots.
    """
    velocity = decoded.velocity
    # obstacles: vertical cylinders, so the barrier lives in the horizontal plane
    centre = np.zeros((*decoded.obstacle_relative.shape[:-1], 3))
    centre[..., :2] = decoded.obstacle_relative
    horizontal = velocity.copy()
    horizontal[..., 2] = 0.0
    obstacle_normal, obstacle_bound = _normal_terms(
        -centre,
        np.broadcast_to(horizontal[..., None, :], centre.shape),
        decoded.obstacle_radius + config.obstacle_margin,
        config.gain,
    )
    # UAVs: i's position and velocity relative to j's, from i's own frame of its slots
    slots = slot_frame(decoded)
    offset = -slots.slots[..., :3]
    rate = velocity[..., None, :] - slots.slots[..., 3:]
    uav_normal, uav_bound = _normal_terms(
        offset, rate, np.asarray(uav_distance + config.separation_margin), config.gain
    )
    # i's half of the bound on the relative acceleration, beyond what the policy already does:
    # the policy moves the formation as a whole (a turn accelerates i and j alike), so only the
    # correction is split between the two, not the common acceleration
    policy_normal = np.einsum("...kc,...c->...k", uav_normal, actions * u_max)
    uav_bound = policy_normal + 0.5 * uav_bound
    present = np.concatenate((decoded.obstacle_present, decoded.slot_present), axis=-1)
    normal = np.concatenate((obstacle_normal, uav_normal), axis=-2)
    bound = np.concatenate((obstacle_bound, uav_bound), axis=-1)
    return np.where(present[..., None], normal, 0.0), np.where(present, bound, _NEVER)


def project_onto_halfspaces(
    x0: np.ndarray,
    normal: np.ndarray,
    bound: np.ndarray,
    half_width: np.ndarray,
    iterations: int,
) -> np.ndarray:
    """``argmin ||x - x0||²`` subject to ``normal_k · x >= bound_k`` and ``|x| <= half_width``.

    Exact (to rounding) where the constraints can all be met: in three dimensions the
    projection onto a non-empty polyhedron is the projection of ``x0`` onto the affine hull of
    at most three of its constraints taken as equalities, so every such set is tried
    (:func:`_exact_projection`, batched over rows and sets) and the nearest feasible point is
    the answer. Where they cannot all be met inside the box, the answer is the box-limited
    compromise of ``iterations`` steps of accelerated projected ascent on the dual
    (:func:`_dual_ascent`).

    Args:
        x0: (M, 3) the points to project.
        normal: (M, K, 3) unit (or zero) normals.
        bound: (M, K) bounds.
        half_width: (M, 3) the box, >= 0.
        iterations: dual ascent steps of the infeasible rows.

    Returns:
        (M, 3) the projection.
    """
    x, feasible = _exact_projection(x0, normal, bound, half_width)
    if not feasible.all():
        rest = ~feasible
        x[rest] = _dual_ascent(x0[rest], normal[rest], bound[rest], half_width[rest], iterations)
    return x


@functools.lru_cache(maxsize=64)
def _active_sets(count: int) -> tuple[np.ndarray, ...]:
    """Index arrays (C_s, s) of every set of s = 1, 2, 3 of ``count`` constraints."""
    return tuple(
        np.array(list(itertools.combinations(range(count), size)), dtype=np.intp).reshape(-1, size)
        for size in (1, 2, 3)
    )


def _exact_projection(
    x0: np.ndarray, normal: np.ndarray, bound: np.ndarray, half_width: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The exact projection of each row and whether its constraints can be met at all (rows
    that cannot keep ``x0``). Shapes as :func:`project_onto_halfspaces`."""
    m = len(x0)
    eye = np.eye(3)
    # the box as six more half-spaces: x_c >= -w_c and -x_c >= -w_c
    box_normal = np.broadcast_to(np.concatenate([eye, -eye]), (m, 6, 3))
    a = np.concatenate([normal, box_normal], axis=1)  # (M, K + 6, 3)
    b = np.concatenate([bound, -half_width, -half_width], axis=1)  # (M, K + 6)
    scale = 1.0 + np.abs(b).max(axis=1, initial=0.0, where=b > _NEVER / 2)
    candidates, distances = [x0[:, None, :]], [np.zeros((m, 1))]
    for sets in _active_sets(a.shape[1]):
        rows, rhs = a[:, sets], b[:, sets]  # (M, C, s, 3), (M, C, s)
        gram = np.einsum("mcid,mcjd->mcij", rows, rows)
        det = np.linalg.det(gram)
        regular = np.abs(det) > 1e-10
        gram = np.where(regular[..., None, None], gram, np.eye(gram.shape[-1]))
        residual = np.einsum("mcid,md->mci", rows, x0) - rhs
        y = np.linalg.solve(gram, residual[..., None])[..., 0]
        x = x0[:, None, :] - np.einsum("mcid,mci->mcd", rows, y)
        x = np.where(regular[..., None], x, np.nan)
        candidates.append(x)
        distances.append(np.einsum("mcd,mcd->mc", x - x0[:, None], x - x0[:, None]))
    x = np.concatenate(candidates, axis=1)  # (M, C, 3)
    distance = np.concatenate(distances, axis=1)
    slack = np.einsum("mkd,mcd->mck", a, x) - b[:, None, :]
    feasible = (slack >= -1e-9 * scale[:, None, None]).all(axis=-1) & np.isfinite(distance)
    distance = np.where(feasible, distance, np.inf)
    best = np.argmin(distance, axis=1)
    found = feasible[np.arange(m), best]
    projected = x[np.arange(m), best]
    return np.where(found[:, None], projected, x0).copy(), found


def _dual_ascent(
    x0: np.ndarray,
    normal: np.ndarray,
    bound: np.ndarray,
    half_width: np.ndarray,
    iterations: int,
) -> np.ndarray:
    """Projected gradient ascent on the dual with Nesterov's acceleration: for multipliers
    λ >= 0 the minimiser over the box is ``clip(x0 + Σ λ_k normal_k)`` and the dual's gradient
    is ``bound - normal · x``, Lipschitz with ``||G||_2² <= ||G||_F²``, so the step is
    ``1 / ||G||_F²``. Where the constraints cannot all be met the multipliers grow and ``x``
    settles at the box-limited compromise. Shapes as :func:`project_onto_halfspaces`."""
    step = 1.0 / np.maximum(np.einsum("mkc,mkc->m", normal, normal), 1e-12)[:, None]
    multiplier = np.zeros(bound.shape)
    ahead = multiplier
    momentum = 1.0
    for _ in range(iterations):
        x = np.clip(x0 + np.einsum("mk,mkc->mc", ahead, normal), -half_width, half_width)
        gradient = bound - np.einsum("mkc,mc->mk", normal, x)
        updated = np.maximum(ahead + step * gradient, 0.0)
        next_momentum = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * momentum**2))
        ahead = updated + ((momentum - 1.0) / next_momentum) * (updated - multiplier)
        multiplier, momentum = updated, next_momentum
    return np.clip(x0 + np.einsum("mk,mkc->mc", multiplier, normal), -half_width, half_width)


class SafetyShield(PolicyBase):
    """``policy`` with a safety shield between it and the plant (module docstring).

    Acts like the wrapped policy (same ``reset``, ``needs_neighbour_index`` and ``records``)
    and counts its interventions: :attr:`uav_steps` acted, :attr:`interventions` changed.

    Args:
        policy: any policy of :func:`~uav_formation_env.policies.registry.make_policy`.
        scenario: the scenario flown, with the local observation layout
            (``observation.kind = "local"``).
        config: margins and gain (None: the defaults).
    """

    accepts_tensors = False

    def __init__(self, policy: Any, scenario: Scenario, config: ShieldConfig | None = None) -> None:
        if scenario.observation.kind != "local":
            raise ValueError(
                f"the safety shield reads the local observation layout; scenario "
                f"{scenario.name!r} has observation.kind = {scenario.observation.kind!r} "
                "(set observation.kind: local)"
            )
        if config is not None and not isinstance(config, ShieldConfig):
            raise ValueError(f"config must be a ShieldConfig or None, got {type(config).__name__}")
        self.policy = as_batch_policy(policy)
        self.scenario = scenario
        self.config = config or ShieldConfig()
        self.needs_neighbour_index = self.policy.needs_neighbour_index
        self.uav_steps = 0
        self.interventions = 0

    def reset(self, batch_size: int = 1, seeds: Sequence[int | None] | None = None) -> None:
        """Reset the wrapped policy (if it has state) and the intervention counts."""
        self.policy.reset(batch_size, seeds=seeds)
        self.uav_steps = 0
        self.interventions = 0

    def records(self) -> Any:
        """The wrapped policy's records (the DMPC's event triggers), if it keeps any."""
        return self.policy.records()

    @property
    def intervention_rate(self) -> float:
        """Fraction of UAV-steps whose action the shield changed (0 before any step)."""
        return self.interventions / self.uav_steps if self.uav_steps else 0.0

    def act_batch(self, obs: np.ndarray, *neighbour_index: np.ndarray) -> np.ndarray:
        """The wrapped policy's (B, N, 3) normalised actions, shielded."""
        actions = np.asarray(self.policy.act_batch(obs, *neighbour_index), dtype=float)
        return self.filter(np.asarray(obs), actions)

    def filter(self, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Shield (B, N, 3) normalised ``actions`` taken on (B, N, dim) local observations."""
        layout = self.scenario.observation
        decoded = decode_local_observations(
            obs, layout.neighbours, layout.obstacles, layout.nearest
        )
        u_max = self.scenario.dynamics.u_max
        half_width = input_half_width(decoded.estimate, u_max) / u_max
        # what the plant will make of the actions: the UAV barriers build on it, and a barrier
        # bound measured from an action beyond the box could not be met inside it
        applied = np.clip(actions, -half_width, half_width)
        normal, bound = barrier_halfspaces(
            decoded, applied, u_max, self.scenario.collision.uav_distance, self.config
        )
        bound = bound / u_max  # in the units of the normalised action
        # a tolerance, so that the UAV rows' bounds of 0 correction never bind by rounding
        violated = (np.einsum("bnkc,bnc->bnk", normal, applied) < bound - _TOLERANCE).any(-1)
        self.uav_steps += violated.size
        if not violated.any():
            return actions
        self.interventions += int(violated.sum())
        shielded = actions.copy()
        shielded[violated] = project_onto_halfspaces(
            actions[violated],
            normal[violated],
            bound[violated],
            half_width[violated],
            self.config.iterations,
        )
        return shielded
