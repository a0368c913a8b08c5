"""Policies that need no optimiser: uniform random actions and the consensus PD heuristic.

Both act on the ``(B, N, dim)`` observations of the evaluation runner and return ``(B, N, 3)``
normalised actions in [-1, 1]. The heuristic's control law lives in
:mod:`uav_formation_env.policies.heuristic`; :class:`HeuristicPolicy` is its adapter that
rebuilds, from each UAV's observation, the view of the swarm the law needs.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import decode_local_observations, slot_frame
from uav_formation_env.core.observation import (
    decode_observations,
    others_index,
    require_decodable,
)
from uav_formation_env.policies.heuristic import ConsensusGains, consensus_pd
from uav_formation_env.policies.protocol import PolicyBase
from uav_formation_env.seeding import check_seed, copy_streams

__all__ = ["HeuristicPolicy", "RandomPolicy"]


class RandomPolicy(PolicyBase):
    """Uniform random normalised actions in [-1, 1]^3 (a lower bound on any controller).

    One stream per copy, seeded from the episode seeds given to :meth:`reset` (see
    :func:`~uav_formation_env.seeding.copy_streams`), so an episode is the same alone or in a
    batch.

    Args:
        seed: the policy's seed, mixed into every copy's stream.
    """

    def __init__(self, seed: int | None = None) -> None:
        self.seed = check_seed(seed, "seed")
        self._rngs: list[np.random.Generator] = []

    def reset(self, batch_size: int = 1, seeds: Sequence[int | None] | None = None) -> None:
        """One stream per copy: from ``(seeds[b], seed)``, or spawned from ``seed``."""
        self._rngs = copy_streams(batch_size, self.seed, seeds)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        batch, n_uav = np.shape(obs)[:2]
        if len(self._rngs) != batch:
            self.reset(batch)
        return np.stack([g.uniform(-1.0, 1.0, size=(n_uav, 3)) for g in self._rngs])


class HeuristicPolicy(PolicyBase):
    """The consensus PD controller (:func:`~uav_formation_env.policies.heuristic.consensus_pd`)
    acting from observations only.

    UAV i rebuilds the swarm in its own frame from its observation: own anchored position 0, own
    velocity, the other UAVs' states from the observed relative formation errors plus the known
    offsets, its neighbour flags as its row of H and its reference velocity; then the shared
    control law is evaluated on that view and UAV i's row is kept. Up to the float32 rounding of
    the observation this is the input the law gives on the simulator's arrays. With the local
    layout the view is UAV i and the UAVs in its k + r slots
    (:func:`~uav_formation_env.core.local_observation.slot_frame`, offsets from the observation),
    so the law sums over the neighbours UAV i sees (the k nearest of its in-neighbours).

    Args:
        scenario: formation offsets, u_max and the offset convention (mission data).
        gains: the PD gains (None: the defaults).
    """

    def __init__(self, scenario: Scenario, gains: ConsensusGains | None = None) -> None:
        require_decodable(scenario, "HeuristicPolicy")
        self.n_uav = scenario.n_uav
        self.u_max = scenario.dynamics.u_max
        self.offsets = scenario.formation.slot_offsets
        self.gains = ConsensusGains() if gains is None else gains
        self.observation = scenario.observation

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=float)
        if self.observation.kind == "local":
            return self._act_local(obs)
        batch, n = obs.shape[:2]
        decoded = decode_observations(obs, n)
        own = np.arange(n)
        index = others_index(n)  # (N, N-1)
        # anchored states a of every UAV as UAV i sees them (own: position 0), (B, N_i, N, 6)
        a_own = np.zeros((batch, n, 6))
        a_own[..., 3:] = decoded.velocity - self.offsets[:, 3:]
        view = np.empty((batch, n, n, 6))
        view[:, own, own] = a_own
        view[:, own[:, None], index] = a_own[:, :, None] + decoded.relative_formation_error
        z = view + self.offsets  # back from anchored to states
        adjacency = np.zeros((batch, n, n, n))
        adjacency[:, own[:, None], own[:, None], index] = decoded.neighbour
        reference = np.broadcast_to(decoded.reference_velocity[:, :, None], (batch, n, n, 3)).copy()
        u = consensus_pd(
            z.reshape(batch * n, n, 6),
            reference.reshape(batch * n, n, 3),
            adjacency.reshape(batch * n, n, n),
            self.offsets,
            self.u_max,
            self.gains,
        ).reshape(batch, n, n, 3)
        return u[:, own, own] / self.u_max

    def _act_local(self, obs: np.ndarray) -> np.ndarray:
        """The law on each UAV's (1 + k)-UAV view: itself (row 0), then its slots."""
        config = self.observation
        decoded = decode_local_observations(
            obs, config.neighbours, config.obstacles, config.nearest
        )
        frame = slot_frame(decoded)
        lead = obs.shape[:-1]  # (B, N)
        rows = int(np.prod(lead))
        k = config.neighbours + config.nearest  # UAV slots
        z = np.concatenate((frame.own[..., None, :], frame.slots), axis=-2).reshape(rows, k + 1, 6)
        offsets = np.concatenate((np.zeros((*lead, 1, 6)), frame.slot_offsets), axis=-2).reshape(
            rows, k + 1, 6
        )
        adjacency = np.zeros((rows, k + 1, k + 1))
        adjacency[:, 0, 1:] = frame.adjacency.reshape(rows, k)
        reference = np.broadcast_to(
            decoded.reference_velocity.reshape(rows, 1, 3), (rows, k + 1, 3)
        )
        u = consensus_pd(z, reference, adjacency, offsets, self.u_max, self.gains)
        return u[:, 0].reshape(*lead, 3) / self.u_max
