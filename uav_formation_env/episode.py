"""The episode layer: what a step means to the agents, for B copies at once.

Every view of the environment (PettingZoo parallel and AEC, Gymnasium, the SB3 VecEnv), the
evaluation runner and the trainer recipes call :class:`FormationEpisodes`; none of them holds a
formula or an episode rule of its own. It owns:

- **actions**: validation (three finite real numbers per agent) and scaling, ``u_n = clip(a, -1,
  1) · u_max``;
- **observations and state**: :meth:`FormationEpisodes.observe` (the per-agent layout of
  :mod:`uav_formation_env.core.observation`) and :meth:`FormationEpisodes.state` (centralised);
- **reward**: minus the stage cost of J_i, minus the collision penalty in ``"penalty"`` mode,
  through the reward transform of ``scenario.episode`` (raw by default);
- **termination**: ``collision.mode == "terminate"`` and a collision, or the formation centroid
  outside the mission corridor (``episode.corridor_width``): the mission failed;
- **truncation**: the scenario's duration, ``episode.max_cycles`` steps after the episode's start,
  or divergence (``episode.max_formation_error``,
  ``episode.max_velocity_error``), which ends a copy without rewarding or punishing it;
- **per-copy autoreset** (``autoreset=True``): a copy whose episode ended is reset at once; its
  last observation is kept as ``final_observation``.

The options (``scenario.episode``, all off by default) are tabled in docs/env.md.

Backends: ``options=SimOptions(backend="torch", device=...)`` runs the simulator and every rule
here on torch tensors (float32 observations, float64 state), the same code as on numpy; actions
may then be tensors on that device (docs/architecture.md, "Backends").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import ModuleType
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.array_api import copy as copy_array
from uav_formation_env.core.array_api import may_hold, namespace, to_numpy
from uav_formation_env.core.cost import anchored
from uav_formation_env.core.dynamics import velocity_setpoint_input
from uav_formation_env.core.local_observation import (
    build_local_observations,
    observation_bounds,
    observation_size,
)
from uav_formation_env.core.observation import (
    DISTANCE_CLIP,
    DISTANCE_SCALE,
    ESTIMATE_SCALE,
    VELOCITY_SCALE,
    build_observations,
)
from uav_formation_env.core.reference import (
    blend_offset,
    next_leg,
    route_error,
    slot_route_offset,
)
from uav_formation_env.core.tracing import call_compiled
from uav_formation_env.core.training_reward import reward_terms, training_reward
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.sim import FormationSim, SeedLike, StepResult
from uav_formation_env.sim_options import SimOptions

__all__ = [
    "EpisodeStep",
    "FormationEpisodes",
    "StepResult",
    "global_state",
    "observation_bounds",
    "observation_size",
    "encode_observations",
    "observations_of",
    "validate_action",
    "validate_actions",
]


def validate_action(agent: str, action: Any) -> np.ndarray:
    """One agent's action as a (3,) float array; ``ValueError`` naming the agent if it is not
    three finite real numbers (strings, complex numbers and objects are refused, not coerced)."""
    value = np.asarray(action)
    if value.dtype.kind not in "biuf":
        raise ValueError(
            f"action of {agent} must be 3 real numbers, got {action!r} (dtype {value.dtype})"
        )
    value = value.astype(float)
    if value.shape != (3,):
        raise ValueError(f"action of {agent} must have shape (3,), got {value.shape}")
    if not np.isfinite(value).all():
        raise ValueError(f"action of {agent} contains NaN or infinite values: {value}")
    return value


def validate_actions(actions: Any, agents: list[str]) -> np.ndarray:
    """An action dict as the clipped (N, 3) array; ``ValueError`` naming the agent if bad."""
    if isinstance(actions, dict) and len(actions) == len(agents):
        # Fast path for a well-formed dict (every step of a normal run): one conversion and one
        # check for all agents. Anything unusual falls through to the agent-by-agent checks,
        # which name the culprit.
        try:
            values = [actions[agent] for agent in agents]
            # real numbers only (no strings or complex numbers coerced), converted once;
            # result_type refuses anything but arrays and numbers (to the checked path)
            real = np.result_type(*values).kind in "iuf"
            stacked = np.array(values, dtype=float) if real else None
        except (KeyError, TypeError, ValueError):
            stacked = None
        if stacked is not None and stacked.shape == (len(agents), 3) and np.isfinite(stacked).all():
            # np.clip for finite values, without its Python wrappers
            return np.minimum(np.maximum(stacked, -1.0), 1.0)
    if not isinstance(actions, dict):
        raise ValueError(f"actions must be a dict {{agent: (3,) array}}, got {type(actions)}")
    unknown = sorted(set(actions) - set(agents))
    if unknown:
        raise ValueError(f"unknown agent(s) {unknown}; expected the agents {agents}")
    missing = [a for a in agents if a not in actions]
    if missing:
        raise ValueError(f"missing action(s) for agent(s) {missing}; every live agent must act")
    stacked = np.stack([validate_action(agent, actions[agent]) for agent in agents])
    return np.clip(stacked, -1.0, 1.0)


def observations_of(sim: FormationSim, result: StepResult) -> np.ndarray:
    """(B, N, dim) float32 observations of a sim step (see :func:`encode_observations`)."""
    return encode_observations(sim, result)[0]


def encode_observations(
    sim: FormationSim, result: StepResult
) -> tuple[np.ndarray, np.ndarray | None]:
    """The observations of a sim step, the one place they are encoded.

    Returns:
        ``(obs, neighbour_index)``: (B, N, dim) float32 observations and, for the local layout,
        the (B, N, k) UAV in each neighbour slot (-1 where absent; who UAV i exchanges plans
        with), else None.
    """
    obs, neighbour_index = _encode_layout(sim, result)
    if sim.scenario.observation.route_offset:
        xp = namespace(obs)
        route = xp.clip(route_offsets(sim, result) / DISTANCE_SCALE, -DISTANCE_CLIP, DISTANCE_CLIP)
        obs = xp.concat((obs, xp.astype(route, obs.dtype)), axis=-1)
    return obs, neighbour_index


def route_offsets(sim: FormationSim, result: StepResult) -> np.ndarray:
    """(B, N, 2) each UAV's horizontal offset from its slot on the preset route [m]
    (:func:`~uav_formation_env.core.reference.slot_route_offset`)."""
    positions = result.z[..., :3]
    slots = anchored(result.z, sim.offsets)[..., :3]
    return slot_route_offset(sim.schedule, result.t, positions, slots, sim.route_start)


def _encode_layout(sim: FormationSim, result: StepResult) -> tuple[np.ndarray, np.ndarray | None]:
    """The observation layout of ``scenario.observation.kind`` (without the route slots)."""
    scenario = sim.scenario
    config = scenario.observation
    fast = None if sim.fast_path is None else sim.fast_path.observation(result)
    if fast is not None:  # the same numbers, computed in the simulator's compiled step
        return fast, None
    if config.kind == "local":
        field = sim.field
        next_velocity, wait = next_leg(sim.schedule, result.t)
        local = build_local_observations(
            result.z,
            result.reference_velocity,
            result.estimate,
            result.adjacency,
            result.avoiding,
            result.t / scenario.duration,
            sim.offsets,
            field.centres,
            field.radii,
            field.present,
            result.min_separation,
            k=config.neighbours,
            m=config.obstacles,
            nearest=config.nearest,
            # the next leg's reference as it would be now (with the route-return term and the
            # corner blend's offset: a policy previews "this reference until the switch, then
            # that one", as the simulator does)
            next_velocity=next_velocity
            + result.route_correction
            + blend_offset(sim.schedule, result.t, scenario.avoidance.turn_blend),
            time_to_switch=wait,
            distance=sim.pair_distances_of(result),
            sensing_radius=config.sensing_radius,
        )
        return local.obs, local.neighbour_index
    full = build_observations(
        result.z,
        result.reference_velocity,
        result.estimate,
        result.adjacency,
        result.avoiding,
        result.t / scenario.duration,
        sim.offsets,
        sim.obstacle_centers,
        sim.obstacle_radii,
        result.min_separation,
        sim.obstacles.present,
    )
    return full, None


def global_state(sim: FormationSim, result: StepResult) -> np.ndarray:
    """(B, 12 N + 1 + N²) float32 global state for centralised critics: positions / 100 m,
    velocities / 20 m/s, reference velocities / 20 m/s, estimates / 0.5 m/s², t / duration, the
    adjacency matrix."""
    batch = result.z.shape[0]
    xp = namespace(result.z)
    parts = (
        result.z[..., :3].reshape(batch, -1) / DISTANCE_SCALE,
        result.z[..., 3:].reshape(batch, -1) / VELOCITY_SCALE,
        result.reference_velocity.reshape(batch, -1) / VELOCITY_SCALE,
        result.estimate.reshape(batch, -1) / ESTIMATE_SCALE,
        (result.t / sim.scenario.duration)[:, None],
        result.adjacency.reshape(batch, -1),
    )
    return xp.astype(xp.concat(parts, axis=-1), xp.float32)


@dataclass(slots=True)
class EpisodeStep:
    """What a reset or a step of B copies means to the agents (arrays over copies B, agents N).

    ``result`` is the simulator's step (the state the reward and the flags describe); with
    autoreset, ``observation`` of a copy that ended is already the first one of its next
    episode, and ``final_observation`` holds the one it ended with.
    """

    observation: np.ndarray  # (B, N, dim) float32
    reward: np.ndarray  # (B, N) after the reward transform
    cost: np.ndarray  # (B, N) stage cost J_i of the transition (raw, untransformed)
    penalty: np.ndarray  # (B, N) collision penalty ("penalty" mode) + corridor penalty
    terminated: np.ndarray  # (B,) bool: collision in "terminate" mode or left the corridor
    truncated: np.ndarray  # (B,) bool: duration reached or diverged (and not terminated)
    left_corridor: np.ndarray  # (B,) bool
    diverged: np.ndarray  # (B,) bool
    result: StepResult
    final_observation: np.ndarray | None = None  # (B, N, dim) where autoreset, else None
    reset: np.ndarray | None = None  # (B,) bool: copies reset after this step (autoreset)
    # (B, N, k) the UAV in each neighbour slot of the local layout (-1: absent), for policies
    # that exchange plans (act_batch(obs, neighbour_index)); None for the full layout
    neighbour_index: np.ndarray | None = None
    # name -> (B, N) weighted kernels of the training reward (reward "train"), else None
    terms: dict[str, np.ndarray] | None = None

    @property
    def collided(self) -> np.ndarray:
        """(B,) bool: some UAV collided in this step."""
        return self.result.collision.any(axis=1)

    @property
    def done(self) -> np.ndarray:
        """(B,) bool: the copy's episode ended in this step."""
        return self.terminated | self.truncated

    @property
    def team_reward(self) -> np.ndarray:
        """(B,) the centralised views' reward: the mean over agents, so that its scale does not
        grow with N."""
        return self.reward.mean(axis=1)


class FormationEpisodes:
    """B copies of a scenario as episodes (see the module docstring for the rules).

    Args:
        scenario: a validated scenario; ``scenario.episode`` holds the training devices.
        batch_size: B.
        autoreset: reset a copy as soon as its episode ends (vectorised training views).
        fly_on_after_collision: do not end episodes on collisions in ``"terminate"`` mode
            (evaluation flies every seed to its end and counts the collisions).
        n_uav: N of a scene distribution that draws N per reset (see
            :class:`~uav_formation_env.sim.FormationSim`).
        options: the simulator's :class:`~uav_formation_env.sim_options.SimOptions` (array
            library, device, compilation, noise source); its backend is also that of every
            array an :class:`EpisodeStep` holds. None: numpy on the CPU.
    """

    def __init__(
        self,
        scenario: Scenario,
        batch_size: int = 1,
        *,
        autoreset: bool = False,
        fly_on_after_collision: bool = False,
        n_uav: int | None = None,
        options: SimOptions | None = None,
    ) -> None:
        self.scenario = scenario
        self.sim = FormationSim(scenario, batch_size=batch_size, n_uav=n_uav, options=options)
        self.batch_size = self.sim.batch_size
        self.n_uav = self.sim.n_uav
        self.u_max = scenario.dynamics.u_max
        self.autoreset = bool(autoreset)
        self.fly_on_after_collision = bool(fly_on_after_collision)
        self.last: EpisodeStep | None = None
        self._flight: FormationSim | None = None  # flies copies to their start step
        self._staggered = False
        # which rules are on, decided once: a plain step allocates nothing for the others
        episode, collision = scenario.episode, scenario.collision
        self._penalty_mode = collision.mode == "penalty"
        self._end_on_collision = collision.mode == "terminate" and not self.fly_on_after_collision
        self._corridor = episode.corridor_width > 0
        self._divergence = episode.max_formation_error > 0 or episode.max_velocity_error > 0
        self._max_cycles = episode.max_cycles
        self._episode_start = copy_array(self.sim.steps)  # (B,) sim step of each episode's start
        self._no_copy = self._constant(np.zeros(self.batch_size, dtype=bool))
        self._no_penalty = self._constant(np.zeros((self.batch_size, self.n_uav)))
        self._compiled: list = []  # SimOptions.compile: _judge through torch.compile

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_compiled"] = []  # a compiled function does not pickle; compiled again on use
        return state

    @property
    def xp(self) -> ModuleType:
        """The simulator's array namespace."""
        return self.sim.xp

    def _constant(self, array: np.ndarray):
        """A constant shared by every step (no allocation per step), on the simulator's device;
        read-only on numpy, so consumers cannot modify it."""
        if self.sim.backend == "numpy":
            return _read_only(array)
        return self.sim._put(array)

    # ------------------------------------------------------------------ reset
    def reset(self, seed: SeedLike = None, mask: np.ndarray | None = None) -> EpisodeStep:
        """Start new episodes in every copy, or in those where ``mask`` is True (see
        :meth:`FormationSim.reset` for ``seed``)."""
        result = self.sim.reset(seed=seed, mask=mask)
        reset = np.ones(self.batch_size, dtype=bool) if mask is None else to_numpy(mask)
        starts = self._start_steps(reset)
        if starts.any():
            result = self._fly_to(starts)
        if self._max_cycles:
            self._episode_start = self.xp.where(
                self.sim._put(reset), self.sim.steps, self._episode_start
            )
        zero, no = self._no_penalty, self._no_copy  # a reset rewards nothing and ends nothing
        obs, neighbour_index = encode_observations(self.sim, result)
        step = EpisodeStep(
            observation=obs,
            reward=zero,
            cost=zero,
            penalty=zero,
            terminated=no,
            truncated=no,
            left_corridor=no,
            diverged=no,
            result=result,
            neighbour_index=neighbour_index,
        )
        self.last = step
        return step

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray) -> EpisodeStep:
        """One control step of every copy.

        Args:
            actions: (B, N, 3) normalised actions; finite values, clipped to [-1, 1].
        """
        if self.last is None:
            raise RuntimeError("call reset() before step()")
        return self._step(self._checked(actions))

    def step_validated(self, actions: np.ndarray) -> EpisodeStep:
        """:meth:`step` for actions already through :func:`validate_actions` ((B, N, 3) finite
        floats in [-1, 1]): the single-copy views validate per agent to name the culprit, and
        checking twice cost 4% of a B = 1 step (measured with callgrind)."""
        if self.last is None:
            raise RuntimeError("call reset() before step()")
        return self._step(actions)

    def _checked(self, actions: np.ndarray) -> np.ndarray:
        """(B, N, 3) actions as finite floats clipped to [-1, 1], or a ValueError naming the
        copy and agent. On torch, a tensor stays on its device (moved to the simulator's)."""
        xp = self.xp
        if self.sim.backend == "numpy" or isinstance(actions, np.ndarray | list | tuple):
            actions = np.asarray(actions)
            if actions.dtype.kind not in "biuf":
                raise ValueError(f"actions must be real numbers, got dtype {actions.dtype}")
            actions = self.sim._put(actions.astype(float))
        elif not xp.isdtype(actions.dtype, ("bool", "integral", "real floating")):
            raise ValueError(f"actions must be real numbers, got dtype {actions.dtype}")
        expected = (self.batch_size, self.n_uav, 3)
        if tuple(actions.shape) != expected:
            raise ValueError(f"actions must have shape {expected}, got {tuple(actions.shape)}")
        if self.sim.backend != "numpy":
            actions = xp.asarray(actions, dtype=xp.float64, device=self.sim.device)
        finite = xp.isfinite(actions)
        if not bool(finite.all()):
            copy, agent = np.argwhere(~to_numpy(finite))[0, :2]
            raise ValueError(
                f"actions contain NaN or infinite values (first: copy {copy}, uav_{agent})"
            )
        # clip for finite values, without numpy's Python wrappers
        return xp.minimum(xp.maximum(actions, -1.0), 1.0)

    def _input(self, clipped: np.ndarray) -> np.ndarray:
        """(B, N, 3) formation input u_n of clipped actions under ``episode.action``."""
        episode = self.scenario.episode
        if episode.action == "velocity":
            return velocity_setpoint_input(
                clipped,
                self.sim.z[..., 3:],
                self.sim.last.reference_velocity,
                episode.velocity_range,
                episode.velocity_gain,
                self.u_max,
            )
        return clipped * self.u_max

    def _step(self, clipped: np.ndarray) -> EpisodeStep:
        result = self.sim.step(self._input(clipped))
        if self.sim.options.compile:  # the rules and observations as one graph
            step = call_compiled(self._compiled, self._judge, result)
        else:
            step = self._judge(result)
        if self.autoreset and (done := step.done).any():
            step.final_observation = step.observation
            step.reset = done
            fresh = self.reset(seed=None, mask=done)
            xp = self.xp
            step.observation = xp.where(done[:, None, None], fresh.observation, step.observation)
            if step.neighbour_index is not None:
                step.neighbour_index = xp.where(
                    done[:, None, None], fresh.neighbour_index, step.neighbour_index
                )
        self.last = step
        return step

    def _judge(self, result: StepResult) -> EpisodeStep:
        """What the simulator's step ``result`` means to the agents: observations, rewards and
        the ending flags (before any autoreset)."""
        cost = result.cost.total
        penalty = self.penalties(result)
        left = self._left_corridor(result) if self._corridor else self._no_copy
        if self._corridor and may_hold(left) and self.scenario.episode.corridor_penalty > 0:
            left_now = self.xp.astype(left[:, None], cost.dtype)  # torch: bool * float is float32
            penalty = penalty + self.scenario.episode.corridor_penalty * left_now
        terminated = left | result.collision.any(axis=1) if self._end_on_collision else left
        diverged = self._diverged(result) & ~terminated if self._divergence else self._no_copy
        if self._max_cycles:
            cycles = (self.sim.steps - self._episode_start) >= self._max_cycles
            truncated = (result.truncated | cycles | diverged) & ~terminated
        elif self._corridor or self._end_on_collision or self._divergence:
            truncated = (result.truncated | diverged) & ~terminated
        else:  # only the duration ends episodes
            truncated = result.truncated
        obs, neighbour_index = encode_observations(self.sim, result)
        terms = None
        if self.scenario.episode.reward == "train":
            terms = self.reward_terms(result)
            penalty_end = self.scenario.episode.train.termination_penalty
            reward = training_reward(terms, terminated, penalty_end)
        else:
            reward = self.reward(cost, penalty)
        return EpisodeStep(
            observation=obs,
            reward=reward,
            cost=cost,
            penalty=penalty,
            terminated=terminated,
            truncated=truncated,
            left_corridor=left,
            diverged=diverged,
            result=result,
            neighbour_index=neighbour_index,
            terms=terms,
        )

    # ------------------------------------------------------------------ start along the mission
    def _start_steps(self, reset: np.ndarray) -> np.ndarray:
        """(B,) the step each reset copy starts at (0 elsewhere), by ``episode.start``."""
        mode, n_steps = self.scenario.episode.start, self.scenario.n_steps
        starts = np.zeros(self.batch_size, dtype=np.int64)
        if mode == "random":
            for b in np.flatnonzero(reset):
                starts[b] = self.sim.generator(b).integers(n_steps)
        elif mode == "staggered" and not self._staggered and reset.all():
            self._staggered = True
            starts = np.arange(self.batch_size) * n_steps // self.batch_size
        return starts

    def _fly_to(self, starts: np.ndarray) -> StepResult:
        """Fly every copy with ``starts > 0`` from its fresh reset to that step with the start
        controller (in a second simulator, so that the other copies do not move), then adopt
        it. Returns the simulator's :class:`StepResult` after the adoption."""
        if self._flight is None:
            sim = self.sim
            options = replace(sim.options, compile=False)
            self._flight = FormationSim(self.scenario, self.batch_size, self.n_uav, options)
            self._flight.adopt(np.ones(self.batch_size, dtype=bool), self.sim)
        flight = self._flight
        pending = starts > 0
        flight.adopt(pending, self.sim)
        result = self.sim.last
        for k in range(1, int(starts.max()) + 1):
            last = flight.last
            # the start controller is a numpy policy: on torch it reads host copies
            u = consensus_pd(
                to_numpy(flight.z),
                to_numpy(last.reference_velocity),
                to_numpy(last.adjacency),
                to_numpy(flight.offsets),
                self.u_max,
            )
            flight.step(u)
            arrived = pending & (starts == k)
            if arrived.any():
                result = self.sim.adopt(arrived, flight)
                pending &= ~arrived
        return result

    # ------------------------------------------------------------------ rules
    def reward_terms(self, result: StepResult) -> dict[str, np.ndarray]:
        """name -> (B, N) weighted kernels of the training reward of a step
        (:mod:`uav_formation_env.core.training_reward`)."""
        offsets = route_offsets(self.sim, result)
        distance = self.xp.linalg.vector_norm(offsets, axis=-1)
        scenario = self.scenario
        degree = self.xp.sum(self.xp.astype(result.adjacency != 0, distance.dtype), axis=-1)
        return reward_terms(
            scenario.episode.train,
            scenario.cost,
            result.cost,
            distance,
            result.obstacle_distance,
            degree,
        )

    def reward(self, cost: np.ndarray, penalty: np.ndarray) -> np.ndarray:
        """(B, N) reward of a stage cost and penalty through ``episode.reward`` (the J_i
        transforms; ``"train"`` is :meth:`reward_terms` summed)."""
        episode = self.scenario.episode
        if episode.reward == "raw":
            return -cost if penalty is self._no_penalty else -(cost + penalty)
        scaled = (cost + penalty) / episode.reward_scale
        return -scaled if episode.reward == "scaled" else -self.xp.log1p(scaled)

    def penalties(self, result: StepResult) -> np.ndarray:
        """(B, N) collision penalty of each agent in this step (0 unless mode is "penalty")."""
        if not self._penalty_mode:
            return self._no_penalty
        # torch: bool * float would be float32
        collided = self.xp.astype(result.collision, result.z.dtype)
        return self.scenario.collision.penalty * collided

    def _left_corridor(self, result: StepResult) -> np.ndarray:
        centroid = result.z[..., :3].mean(axis=1)
        off = route_error(self.sim.schedule, result.t, centroid, self.sim.route_start)
        return off > self.scenario.episode.corridor_width

    def _diverged(self, result: StepResult) -> np.ndarray:
        episode = self.scenario.episode
        xp = self.xp
        diverged = self._no_copy
        if episode.max_formation_error > 0:
            a = anchored(result.z, self.sim.offsets)[..., :3]
            spread = xp.linalg.vector_norm(a - xp.mean(a, axis=1, keepdims=True), axis=-1)
            diverged = diverged | (xp.max(spread, axis=1) > episode.max_formation_error)
        if episode.max_velocity_error > 0:
            error = xp.linalg.vector_norm(result.z[..., 3:] - result.reference_velocity, axis=-1)
            diverged = diverged | (xp.max(error, axis=1) > episode.max_velocity_error)
        return diverged

    # ------------------------------------------------------------------ views
    def observe(self) -> np.ndarray:
        """(B, N, dim) the agents' current observations."""
        if self.last is None:
            raise RuntimeError("call reset() first")
        return self.last.observation

    def state(self) -> np.ndarray:
        """(B, 12 N + 1 + N²) the current global state (:func:`global_state`)."""
        if self.last is None:
            raise RuntimeError("call reset() first")
        return global_state(self.sim, self.sim.last)


def _read_only(array: np.ndarray) -> np.ndarray:
    """A constant shared by every step (no allocation per step); consumers cannot modify it."""
    array.flags.writeable = False
    return array
