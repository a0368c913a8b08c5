"""Nash-seeking distributed MPC (docs/model.md §4.3, §5, §6): the paper's reference policy.

The policy object plays all N distributed controllers of B scenario copies at once and relays
their messages. UAV i acts only on its own observation, the mission data every UAV carries
(formation offsets, cost weights, horizon, schedule) and its neighbours' last broadcast plans,
in its own frame (:mod:`uav_formation_env.policies.broadcast`). Per control step, for every UAV
at once (a Jacobi best-response step): warm start from the shifted last plan (eq. 20), predict
the neighbours under their received plans, evaluate ``J_pre = J_i(W_i)`` with the one
definition of J_i, and if ``J_pre`` exceeds the event threshold minimise J_i over the input box
with PIO / LFPIO / PSO (or exactly: ``"exact"``; to a Nash equilibrium: ``"nash"``), never
returning worse than the warm start; apply the first input and broadcast the sequence.

The solvers live in :mod:`uav_formation_env.policies.dmpc_step`. Randomness: one numpy
generator per copy seeded from its episode's seed (``random="generator"``), or counter-based
draws computed where they are used (``random="counter"``). Observations may be numpy or torch
tensors on any device. The full specification (information pattern, algorithm, backends,
randomness) is docs/reference_policy.md, "The distributed-MPC Nash policy".
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario
from uav_formation_env.core.array_api import as_float, namespace_of, to_numpy
from uav_formation_env.core.local_observation import (
    DecodedLocalObservation,
    decode_local_observations,
    observation_bounds,
    observation_size,
)
from uav_formation_env.core.observation import (
    DecodedObservation,
    decode_observations,
    require_decodable,
)
from uav_formation_env.policies.broadcast import shift_warm_start
from uav_formation_env.policies.dmpc_step import (
    CounterKeys,
    DMPCRecords,
    MetaheuristicSolver,
    StepRecord,
    TriggeredRounds,
    step_solver,
)
from uav_formation_env.policies.protocol import PolicyBase
from uav_formation_env.policies.solvers import DMPC_OPTIMIZERS, SolverConfig, solver_config
from uav_formation_env.seeding import check_seed, copy_streams

__all__ = [
    "DEFAULT_THRESHOLD",
    "DMPCRecords",
    "NashDMPCPolicy",
    "POLICY_OPTIMIZERS",
    "StepRecord",
    "shift_warm_start",
]

DEFAULT_THRESHOLD = 10.0  # event-trigger threshold on J_i(W) (docs/model.md §5) [-]

POLICY_OPTIMIZERS = DMPC_OPTIMIZERS  # the solver names NashDMPCPolicy accepts

RANDOM_SOURCES = ("generator", "counter")  # NashDMPCPolicy(random=...)


class NashDMPCPolicy(PolicyBase):
    """Distributed MPC in which every UAV best-responds to its neighbours' broadcast plans.

    Acts from observations only (see the module docstring). ``act_batch`` is the core API; ``act``
    serves the PettingZoo ParallelEnv and ``predict`` stable-baselines3's ``evaluate_policy``.

    Args:
        scenario: the scenario (or its name, YAML path or mapping): offsets, weights, horizon, δ,
            duration, u_max and the preset-velocity schedule.
        optimizer: ``"lfpio"`` (the paper's), ``"pio"``, ``"pso"`` (same budget as LFPIO by
            default), ``"exact"`` (exact best response), ``"nash"`` (iterated exact best
            responses to an equilibrium each step), or a :class:`PIOConfig` /
            :class:`LFPIOConfig` / :class:`PSOConfig` / :class:`ExactConfig` /
            :class:`NashConfig` (the last sets the sweep cap, tolerance and Jacobi /
            Gauss-Seidel).
        seed: policy seed: mixed into every copy's stream with the episode seeds of
            :meth:`reset`, or, without them, the root the copies' streams are spawned from
            (None: fresh entropy).
        threshold: event-trigger threshold on J_i(W) [-].
        inner_rounds: K exchange / re-optimise rounds per step (docs/model.md §5; 1 = the paper;
            must be 1 for ``"nash"``, which iterates to equilibrium itself).
        population_cost: how the optimiser's populations are evaluated: ``"quadratic"`` (J_i's
            exact quadratic coefficients, identified once per step from the one definition, plus
            the separation term of the pairs that can be active in the search box, see
            :meth:`~uav_formation_env.core.cost.HorizonCost.quadratic`; fast) or ``"direct"``
            (:meth:`~uav_formation_env.core.cost.HorizonCost.terms` on every population). Both
            agree to rounding (~1e-13 relative); J_pre, J_exec and the never-worse-than-W check
            always use the direct evaluation.
        random: ``"generator"`` (each copy's numpy generator, on the host) or ``"counter"``
            (counter-based draws on the observations' device; a UAV's numbers depend only on
            the seeds, itself and the step, not on the batch or on which other UAVs trigger).
    """

    def __init__(
        self,
        scenario: Scenario | str | Path | Mapping[str, Any] = "paper",
        optimizer: str | SolverConfig = "lfpio",
        seed: int | None = None,
        threshold: float = DEFAULT_THRESHOLD,
        inner_rounds: int = 1,
        population_cost: str = "quadratic",
        random: str = "generator",
    ) -> None:
        if random not in RANDOM_SOURCES:
            raise ValueError(f"random must be one of {RANDOM_SOURCES}, got {random!r}")
        if population_cost not in ("quadratic", "direct"):
            raise ValueError(
                f"population_cost must be 'quadratic' or 'direct', got {population_cost!r}"
            )
        if not isinstance(inner_rounds, int | np.integer) or inner_rounds < 1:
            raise ValueError(f"inner_rounds must be an integer >= 1, got {inner_rounds!r}")
        if not np.isfinite(threshold):
            raise ValueError(f"threshold must be finite, got {threshold!r}")
        self.scenario = resolve_scenario(scenario)
        self.optimizer = solver_config(optimizer)
        self._solver = step_solver(self.optimizer, self.scenario, inner_rounds, population_cost)
        self.threshold = float(threshold)
        self.inner_rounds = int(inner_rounds)
        self.population_cost = population_cost
        self.random = random
        self.seed = check_seed(seed, "seed")
        self._keys: CounterKeys | None = None
        self._rngs: list[np.random.Generator] = []
        self._fresh = False  # reset() was called and no step taken since
        sc = self.scenario
        require_decodable(sc, "NashDMPCPolicy")
        # With the local layout UAV i sees its k slots and exchanges plans with the UAVs in them
        # (the neighbour_index that comes with the observation); N may change between episodes.
        self.local = sc.observation.kind == "local"
        self.needs_neighbour_index = self.local
        self.n_uav = sc.n_uav
        self.horizon = sc.cost.horizon
        self.dt = sc.dynamics.dt
        self.u_max = sc.dynamics.u_max
        self.obs_dim = observation_size(sc)
        # the observation space: far outside it the costs overflow and every candidate ties
        self._obs_bounds = tuple(b.astype(np.float64) for b in observation_bounds(sc))
        self.agents = [f"uav_{i}" for i in range(self.n_uav)]
        self._plans: Any = None  # (B, N, H, 3) last broadcast plans [m/s^2], numpy or torch
        self._records: list[StepRecord] = []
        self._wall: list[float] = []

    # ------------------------------------------------------------------ state
    def reset(
        self,
        batch_size: int = 1,
        seeds: Sequence[int | None] | None = None,
    ) -> None:
        """Clear the broadcast plans (so W = 0 at the next step) and the records, and seed one
        random stream per copy.

        Called automatically (keeping the streams) when every copy's observation shows t = 0
        after a step; when B changes, the streams are spawned anew from the policy seed. Copies
        that restart alone only have their plans cleared.

        Args:
            batch_size: number of scenario copies B.
            seeds: the episode seed of each copy (non-negative ints, or None for a copy without
                one); copy b's stream is seeded from ``(seeds[b], seed)``. None: every copy's
                stream is spawned from the policy's ``seed``.
        """
        if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer):
            raise TypeError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        if seeds is not None:
            seeds = [check_seed(s, f"seeds[{b}]") for b, s in enumerate(seeds)]
            if len(seeds) != batch_size:
                raise ValueError(
                    f"seeds must hold {batch_size} seeds (one per copy), got {len(seeds)}"
                )
        self._rngs = copy_streams(int(batch_size), self.seed, seeds)
        # counter keys: two words of each copy's seed sequence (from the same seeds as its
        # stream; generating them leaves the stream untouched)
        self._keys = CounterKeys(
            np.stack(
                [g.bit_generator.seed_seq.generate_state(2, np.uint32) for g in self._rngs]
            ).astype(np.int64)
        )
        self._fresh = True
        self._plans = np.zeros((int(batch_size), self.n_uav, self.horizon, 3))
        self._records = []
        self._wall = []

    @property
    def accepts_tensors(self) -> bool:
        """Whether :meth:`act_batch` takes torch observations and acts on their device (the
        metaheuristics; see "Backends" in the module docstring)."""
        solver = self._solver
        return isinstance(solver, TriggeredRounds) and isinstance(
            solver.solver, MetaheuristicSolver
        )

    @property
    def streams(self) -> tuple[np.random.Generator, ...]:
        """The random generator of each copy (set by :meth:`reset`)."""
        return tuple(self._rngs)

    @property
    def plans(self) -> np.ndarray:
        """(B, N, H, 3) the sequences every UAV broadcast at the last step [m/s^2] (a numpy
        copy, also when the policy acts on tensors)."""
        if self._plans is None:
            raise RuntimeError("no plans yet: call reset() or act first")
        return np.array(to_numpy(self._plans))

    @plans.setter
    def plans(self, value: np.ndarray) -> None:
        value = np.array(value, dtype=float)
        n_ok = self.local or (value.ndim == 4 and value.shape[1] == self.n_uav)
        if value.ndim != 4 or value.shape[2:] != (self.horizon, 3) or not n_ok:
            n_text = "N" if self.local else str(self.n_uav)
            raise ValueError(
                f"plans must have shape (B, {n_text}, {self.horizon}, 3), got {value.shape}"
            )
        self._plans = value

    def warm_starts(self) -> np.ndarray:
        """(B, N, H, 3) every UAV's warm start W_i for the next step (eq. 20) [m/s^2]."""
        return shift_warm_start(self.plans)

    # ------------------------------------------------------------------ acting
    def act_batch(self, obs: Any, neighbour_index: np.ndarray | None = None) -> Any:
        """One control step of every UAV of every copy.

        Args:
            obs: (B, N, dim) observations of :func:`~uav_formation_env.episode.observations_of`
                (agent order uav_0..uav_{N-1}); numpy, or a torch tensor (see "Backends" in
                the module docstring).
            neighbour_index: (B, N, k) the UAV in each neighbour slot of the local layout
                (:attr:`~uav_formation_env.episode.EpisodeStep.neighbour_index`): whose plans a
                UAV receives. Required with ``observation.kind = "local"``, else unused.

        Returns:
            (B, N, 3) normalised actions ``u_n(0|t) / u_max`` in [-1, 1], float64, in the library
            and on the device of ``obs``.
        """
        start = time.perf_counter()
        decoded = self._decode(obs, neighbour_index)
        self._restart(decoded.time_fraction[:, 0] == 0.0, decoded.velocity.shape[1])
        assert self._plans is not None
        self._plans = as_float(self._plans, decoded.velocity)  # onto the observations' device
        source = self._keys if self.random == "counter" else self._rngs
        assert source is not None
        output, record = self._solver.step(decoded, self._plans, self.threshold, source)
        self._plans = output
        self._records.append(record)
        self._wall.append(time.perf_counter() - start)
        return namespace_of(output).clip(output[..., 0, :] / self.u_max, -1.0, 1.0)

    def _decode(
        self, obs: np.ndarray, neighbour_index: np.ndarray | None
    ) -> DecodedObservation | DecodedLocalObservation:
        """Check and decode (B, N, dim) observations; a ValueError names what is wrong."""
        if isinstance(obs, np.ndarray) or not hasattr(obs, "device"):
            obs = np.asarray(obs, dtype=np.float64)
        elif not self.accepts_tensors:
            raise ValueError(
                "obs is a tensor, but this policy runs on numpy only ('exact' and 'nash' are "
                "numpy-only; PIO, LFPIO and PSO run on torch); pass numpy observations"
            )
        xp = namespace_of(obs)
        n_text = "N" if self.local else str(self.n_uav)
        if (
            obs.ndim != 3
            or obs.shape[2] != self.obs_dim
            or (not self.local and obs.shape[1] != self.n_uav)
        ):
            shape = tuple(obs.shape)
            raise ValueError(f"obs must have shape (B, {n_text}, {self.obs_dim}), got {shape}")
        if not bool(xp.all(xp.isfinite(obs))):
            copy, agent = np.argwhere(~np.isfinite(to_numpy(obs)))[0, :2]
            raise ValueError(
                f"obs contains NaN or infinite values (first: copy {copy}, uav_{agent}); a "
                "policy cannot act on them"
            )
        low, high = (xp.asarray(b, dtype=obs.dtype, device=obs.device) for b in self._obs_bounds)
        outside = (obs < low) | (obs > high)
        if bool(xp.any(outside)):
            copy, agent, slot = np.argwhere(to_numpy(outside))[0]
            value = float(to_numpy(obs)[copy, agent, slot])
            raise ValueError(
                f"obs outside the observation space (first: copy {copy}, uav_{agent}, slot "
                f"{slot} = {value:g}, bounds [{self._obs_bounds[0][slot]:g}, "
                f"{self._obs_bounds[1][slot]:g}]); a policy cannot act on them"
            )
        if not self.local:
            return decode_observations(obs, self.n_uav)
        if neighbour_index is None:
            raise ValueError(
                "neighbour_index is required with observation.kind='local': the UAV in each "
                "neighbour slot (EpisodeStep.neighbour_index), whose plans a UAV receives"
            )
        config = self.scenario.observation
        return decode_local_observations(
            obs,
            config.neighbours,
            config.obstacles,
            config.nearest,
            neighbour_index=neighbour_index,
        )

    def act(
        self, observations: Mapping[str, np.ndarray], neighbour_index: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """ParallelEnv convenience: one copy (B = 1), agents ``uav_0 .. uav_{N-1}``.

        Args:
            observations: agent -> (dim,) observation; every agent must be present (with the
                local layout, the agents of the episode: uav_0 .. uav_{N-1} for its N).
            neighbour_index: (N, k) the UAV in each neighbour slot (local layout only; the
                ParallelEnv's ``neighbour_index``).

        Returns:
            agent -> (3,) float32 normalised action.
        """
        agents = [f"uav_{i}" for i in range(len(observations))] if self.local else self.agents
        missing = [a for a in agents if a not in observations]
        if missing:
            raise KeyError(f"observations lack agents {missing}")
        obs = np.stack([np.asarray(observations[a]) for a in agents])[None]
        index = None if neighbour_index is None else np.asarray(neighbour_index)[None]
        actions = self.act_batch(obs, index)[0].astype(np.float32)
        return {a: actions[i] for i, a in enumerate(agents)}

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """stable-baselines3 interface (``evaluate_policy``) over a per-agent vector env.

        Args:
            observation: (B·N, dim), stacked per (copy, agent): B copies of N agents.
            state: passed through (the plans live in the policy object).
            episode_start: (B·N,) bool; copies whose agents all start an episode have their
                plans cleared (t = 0 in the observation does the same).
            deterministic: ignored; the policy is deterministic given its seed.

        Returns:
            ``(actions, state)`` with actions (B·N, 3) float32 in [-1, 1].
        """
        if self.local:
            raise ValueError(
                "predict() serves per-agent vector envs of the full layout; with "
                "observation.kind='local' call act_batch(obs, neighbour_index)"
            )
        obs = np.asarray(observation)
        if obs.ndim != 2 or obs.shape[0] % self.n_uav or obs.shape[1] != self.obs_dim:
            raise ValueError(
                f"observation must have shape (B*{self.n_uav}, {self.obs_dim}), got {obs.shape}"
            )
        obs = obs.reshape(-1, self.n_uav, self.obs_dim)
        if episode_start is not None and self._plans is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1, self.n_uav).all(axis=1)
            if starts.shape[0] == self._plans.shape[0]:
                self._plans[starts] = 0.0
        actions = self.act_batch(obs)
        return actions.reshape(-1, 3).astype(np.float32), state

    # ------------------------------------------------------------------ records
    def records(self) -> DMPCRecords:
        """The per-step records since the last (automatic) reset, as arrays."""
        batch, n_uav = (1, self.n_uav) if self._plans is None else self._plans.shape[:2]
        return DMPCRecords.from_steps(self._records, self._wall, batch, n_uav)

    def trigger_counts(self) -> np.ndarray:
        """(B, N) number of triggered steps per copy and UAV since the last reset."""
        return self.records().triggered.sum(axis=0)

    # ------------------------------------------------------------------ internals
    def _restart(self, restart: np.ndarray, n_uav: int) -> None:
        batch = restart.shape[0]
        if self._plans is None or self._plans.shape[0] != batch:
            self.reset(batch)
        assert self._plans is not None
        if self._plans.shape[1] != n_uav:  # the local layout: a new episode of another N
            if not bool(restart.all()):
                raise ValueError(
                    f"obs holds {n_uav} UAVs, but the episodes under way have "
                    f"{self._plans.shape[1]}; N may change only when every copy starts anew"
                )
            self._plans = np.zeros((batch, n_uav, self.horizon, 3))
        elif bool(restart.all()) and not self._fresh:
            # a new episode in every copy: the copies' streams go on
            self._plans[:] = 0.0
            self._records = []
            self._wall = []
        elif bool(restart.any()):
            self._plans = as_float(self._plans, restart)
            self._plans[restart] = 0.0
        self._fresh = False
