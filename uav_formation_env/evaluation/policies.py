"""Policy adapters for the evaluation runner: random, heuristic, a saved SB3 model, by name."""

from __future__ import annotations

import pickle
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.cost import relative_offset_sign
from uav_formation_env.core.observation import decode_observations, observation_dim, others_index
from uav_formation_env.extras import require
from uav_formation_env.policies.heuristic import ConsensusGains, consensus_pd
from uav_formation_env.seeding import check_seed, copy_streams

DMPC_OPTIMIZERS = ("lfpio", "pio", "pso", "exact", "nash")
POLICY_NAMES = (*DMPC_OPTIMIZERS, "heuristic", "random")
SB3_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")


class BatchPolicy(Protocol):
    """What :func:`run_episodes` needs of a policy (``reset(batch_size, seeds)`` optional)."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray: ...


class RandomPolicy:
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


class HeuristicPolicy:
    """The consensus PD controller (:func:`~uav_formation_env.policies.heuristic.consensus_pd`)
    acting from observations only.

    UAV i rebuilds the swarm in its own frame from its observation: own anchored position 0, own
    velocity, the other UAVs' states from the observed relative formation errors plus the known
    offsets, its neighbour flags as its row of H and its reference velocity; then the shared
    control law is evaluated on that view and UAV i's row is kept. Up to the float32 rounding of
    the observation this is the input the law gives on the simulator's arrays.

    Args:
        scenario: formation offsets, u_max and the offset convention (mission data).
        gains: the PD gains (None: the defaults).
    """

    def __init__(self, scenario: Scenario, gains: ConsensusGains | None = None) -> None:
        self.n_uav = scenario.n_uav
        self.u_max = scenario.dynamics.u_max
        self.offsets = np.asarray(scenario.formation.offsets, dtype=float)
        self.mirrored = scenario.formation.mirrored_offsets
        self.gains = ConsensusGains() if gains is None else gains

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=float)
        batch, n = obs.shape[:2]
        decoded = decode_observations(obs, n)
        sign = relative_offset_sign(self.mirrored)
        own = np.arange(n)
        index = others_index(n)  # (N, N-1)
        # anchored states a of every UAV as UAV i sees them (own: position 0), (B, N_i, N, 6)
        a_own = np.zeros((batch, n, 6))
        a_own[..., 3:] = decoded.velocity - sign * self.offsets[:, 3:]
        view = np.empty((batch, n, n, 6))
        view[:, own, own] = a_own
        view[:, own[:, None], index] = a_own[:, :, None] + decoded.relative_formation_error
        z = view + sign * self.offsets  # back from anchored to states
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
            self.mirrored,
        ).reshape(batch, n, n, 3)
        return u[:, own, own] / self.u_max


class SB3Policy:
    """A saved stable-baselines3 model shared by every UAV (parameter sharing).

    stable-baselines3 is imported only here, when the model is loaded (the ``[rl]`` extra). The
    algorithm is ``algo`` or, if None, the first of :data:`SB3_ALGORITHMS` that loads the file.
    If ``vecnormalize.pkl`` lies beside the model, observations are normalised with its running
    statistics (not updated). Predictions are deterministic, on ``(B·N, dim)`` observations.

    Args:
        path: the model's ``.zip``.
        algo: algorithm class name (``"PPO"``, ``"SAC"``, ...) or None to try each.
        device: torch device.
    """

    def __init__(self, path: str | Path, algo: str | None = None, device: str = "cpu") -> None:
        self.path = Path(path)
        if not self.path.is_file() and self.path.with_suffix(".zip").is_file():
            self.path = self.path.with_suffix(".zip")
        if not self.path.is_file():
            raise FileNotFoundError(f"model file not found: {str(path)!r}")
        stable_baselines3 = require("stable_baselines3", "a stable-baselines3 model policy")
        names = [algo.upper()] if algo else list(SB3_ALGORITHMS)
        errors = []
        self.model = None
        for name in names:
            cls = getattr(stable_baselines3, name, None)
            if cls is None:
                errors.append(f"{name}: not a stable-baselines3 algorithm")
                continue
            try:
                self.model = cls.load(str(self.path), device=device)
                self.algo = name
                break
            except Exception as error:  # noqa: BLE001 - try the next algorithm
                errors.append(f"{name}: {type(error).__name__}: {error}")
        if self.model is None:
            raise ValueError(f"could not load {self.path} as {names}: " + "; ".join(errors))
        self.normalizer = None
        stats = self.path.parent / "vecnormalize.pkl"
        if stats.is_file():
            with open(stats, "rb") as stream:
                self.normalizer = pickle.load(stream)  # VecNormalize without its venv
            self.normalizer.training = False

    @classmethod
    def from_model(cls, model: Any, normalizer: Any | None = None) -> SB3Policy:
        """A policy from a model in memory (e.g. during training) and its VecNormalize.

        The normaliser's statistics are read, never updated, by :meth:`act_batch`.
        """
        policy = cls.__new__(cls)
        policy.path, policy.model, policy.normalizer = None, model, normalizer
        policy.algo = type(model).__name__
        return policy

    @property
    def observation_size(self) -> int:
        """Number of observation values the model takes."""
        return int(np.prod(self.model.observation_space.shape))

    def check_scenario(self, scenario: Scenario) -> None:
        """``ValueError`` naming both sizes if the model cannot act on ``scenario``'s
        observations."""
        expected = observation_dim(scenario.n_uav)
        if self.observation_size != expected:
            raise ValueError(
                f"the model {self._name()} takes observations of {self.observation_size} values, "
                f"but scenario {scenario.name!r} ({scenario.n_uav} UAVs) gives {expected}: it was "
                "trained on a scenario with another number of UAVs"
            )

    def _name(self) -> str:
        return repr(str(self.path)) if self.path is not None else "in memory"

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        batch, n, dim = obs.shape
        if dim != self.observation_size:
            raise ValueError(
                f"the model {self._name()} takes observations of {self.observation_size} values, "
                f"got {dim} ({n} UAVs)"
            )
        flat = obs.reshape(batch * n, dim)
        if self.normalizer is not None:
            flat = self.normalizer.normalize_obs(flat)
        actions, _ = self.model.predict(flat, deterministic=True)
        return np.clip(np.asarray(actions, dtype=float).reshape(batch, n, 3), -1.0, 1.0)


def make_policy(
    name: str, scenario: Scenario, seed: int | None = None, algo: str | None = None
) -> BatchPolicy:
    """A policy from a name: ``lfpio``, ``pio``, ``pso`` (the reference DMPC with that optimiser),
    ``exact`` (its best response solved exactly), ``nash`` (best responses iterated to a Nash
    equilibrium every step), ``heuristic``, ``random``, or the path of a stable-baselines3 model.

    Args:
        name: policy name or model path.
        scenario: the scenario the policy flies (mission data of DMPC / heuristic).
        seed: the policy's own seed, mixed into the per-episode random streams of the DMPC
            optimisers and the random policy (None: the episode seeds alone decide).
        algo: stable-baselines3 algorithm of a model path (None: try each).
    """
    key = name.lower()
    if key in DMPC_OPTIMIZERS:
        from uav_formation_env.policies.dmpc import NashDMPCPolicy

        return NashDMPCPolicy(scenario, key, seed=seed)
    if key == "heuristic":
        return HeuristicPolicy(scenario)
    if key == "random":
        return RandomPolicy(seed)
    path = Path(name)
    if path.is_file() or path.with_suffix(".zip").is_file():
        policy = SB3Policy(path, algo)
        policy.check_scenario(scenario)
        return policy
    if path.suffix == ".zip" or len(path.parts) > 1:
        raise FileNotFoundError(f"policy model file not found: {name!r}")
    raise ValueError(
        f"unknown policy {name!r}: expected one of {list(POLICY_NAMES)} or the path of a "
        "stable-baselines3 model (.zip)"
    )
