"""The batched episode runner: every seed one copy of one FormationSim, one policy call per step."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.core.array_api import to_numpy
from uav_formation_env.core.observation import decode_observations
from uav_formation_env.core.topology import obstacle_distances
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.broadcast import input_half_width
from uav_formation_env.policies.nash import nash_gap as measure_nash_gap
from uav_formation_env.policies.protocol import BatchPolicy, as_batch_policy
from uav_formation_env.scenes import seeds_by_n_uav
from uav_formation_env.seeding import check_seed
from uav_formation_env.sim_options import SimOptions


@dataclass
class EpisodeBatch:
    """Every step of B episodes run together (one per seed); T control steps, N UAVs, O obstacles.

    Arrays indexed ``[k]`` over T + 1 hold the state at time ``t[k]`` (k = 0 is the reset);
    arrays over T hold what happened during step k + 1 (from ``t[k]`` to ``t[k + 1]``).
    """

    scenario: Scenario
    seeds: list[int]
    policy_name: str
    t: np.ndarray  # (T+1,) [s]
    z: np.ndarray  # (T+1, B, N, 6) [m, m/s]
    reference_velocity: np.ndarray  # (T+1, B, N, 3) [m/s]
    estimate: np.ndarray  # (T+1, B, N, 3) observer estimate [m/s^2]
    groups: np.ndarray  # (T+1, B, N) sub-formation id
    min_separation: np.ndarray  # (T+1, B, N) [m]
    obstacle_surface: np.ndarray  # (T+1, B, N) nearest obstacle surface [m]
    obstacle_center: np.ndarray  # (T+1, B, O) min over UAVs of the distance to each centre [m]
    u_n: np.ndarray  # (T, B, N, 3) formation input [m/s^2]
    u_applied: np.ndarray  # (T, B, N, 3) [m/s^2]
    disturbance: np.ndarray  # (T, B, N, 3) [m/s^2]
    stage_cost: np.ndarray  # (T, B, N) J_i stage cost of the transition
    cost_terms: dict[str, np.ndarray]  # name -> (T, B, N)
    reward: np.ndarray  # (T, B, N) the episode layer's reward (scenario.episode.reward)
    collision: np.ndarray  # (T, B, N) bool, after the step
    activation_time: np.ndarray  # (B, O) [s], NaN if never
    restore_time: np.ndarray  # (B, O) [s], NaN if never
    case: np.ndarray  # (B, O) 1 one group, 2 split, 0 never activated
    triggered: np.ndarray | None  # (T, B, N) policy's event trigger (DMPC), else None
    j_pre: np.ndarray | None  # (T, B, N)
    j_exec: np.ndarray | None  # (T, B, N)
    policy_seconds: np.ndarray  # (T,) wall time of act_batch per step [s]
    sim_seconds: np.ndarray  # (T,) wall time of the simulation step + observations [s]
    # Nash gap of the policy's plans at each step (run_episodes(nash_gap=True)), else None
    nash_gap: np.ndarray | None = None  # (T, B, N) J_i(plan) - min J_i, others' plans fixed
    nash_cost: np.ndarray | None = None  # (T, B, N) J_i of the plan over the horizon
    nash_in_box: np.ndarray | None = None  # (T, B, N) bool, the plan lies in the UAV's box
    # the concrete scenario of each episode (a scene distribution draws one per seed), else None
    scenes: list[Scenario] | None = None

    @property
    def n_steps(self) -> int:
        return len(self.t) - 1

    @property
    def batch_size(self) -> int:
        return len(self.seeds)

    @property
    def wall_seconds(self) -> float:
        return float(self.policy_seconds.sum() + self.sim_seconds.sum())


# EpisodeBatch fields whose batch axis is the first (B, O); the time series have it second
_BATCH_FIRST = ("activation_time", "restore_time", "case")
# summed over parts: the compute time of every part's step
_TIMINGS = ("policy_seconds", "sim_seconds")


def concatenate_batches(parts: Sequence[EpisodeBatch]) -> EpisodeBatch:
    """One batch of the episodes of ``parts`` (same scenario, policy and length), in order.

    Every copy's numbers depend on its seed alone, so a batch run in parts (for example as Ray
    tasks) equals the batch run at once, up to the wall times: ``policy_seconds`` and
    ``sim_seconds`` become the parts' summed compute time per step.
    """
    if not parts:
        raise ValueError("concatenate_batches needs at least one batch")
    first = parts[0]
    if any(p.scenario != first.scenario or p.n_steps != first.n_steps for p in parts):
        raise ValueError("batches of different scenarios or lengths cannot be concatenated")
    fields: dict = {"seeds": [s for p in parts for s in p.seeds]}
    for f in dataclasses.fields(EpisodeBatch):
        name = f.name
        values = [getattr(p, name) for p in parts]
        if name in ("scenario", "seeds", "policy_name", "t"):
            fields.setdefault(name, values[0])
        elif name == "scenes":
            fields[name] = None if values[0] is None else [s for v in values for s in v]
        elif name in _TIMINGS:
            fields[name] = np.sum(values, axis=0)
        elif name == "cost_terms":
            fields[name] = {k: np.concatenate([v[k] for v in values], axis=1) for k in values[0]}
        elif any(v is None for v in values):
            fields[name] = None
        else:
            fields[name] = np.concatenate(values, axis=0 if name in _BATCH_FIRST else 1)
    return EpisodeBatch(**fields)


ProgressLike = bool | Callable[[int], None]


def run_episodes(
    scenario: Scenario,
    policy: BatchPolicy,
    seeds: Sequence[int],
    *,
    duration: float | None = None,
    policy_name: str = "",
    progress: ProgressLike = False,
    desc: str | None = None,
    nash_gap: bool = False,
    n_uav: int | None = None,
    options: SimOptions | None = None,
) -> EpisodeBatch:
    """Run one episode per seed, all seeds as one batch, with one ``act_batch`` call per step.

    Copy b is seeded with ``seeds[b]`` (a copy reproduces a one-seed run of that seed). A
    scenario that draws N per reset needs seeds that all draw one N, ``n_uav`` (None: the N
    they draw); :func:`run_episode_groups` groups seeds of several N.

    Args:
        scenario: the scenario.
        policy: see the module docstring; it must have been built for ``scenario`` with the same
            ``duration`` (the observation carries t / duration).
        seeds: one seed per episode.
        duration: episode length [s] overriding the scenario's (None: the scenario's).
        policy_name: label stored in the result.
        progress: True for a tqdm bar over the steps, or a callable given the number of steps
            done since its last call.
        desc: label of the progress bar.
        nash_gap: also measure, at every step, how far the policy's plans are from a Nash
            equilibrium of the horizon game (:func:`policy_plans`,
            :func:`~uav_formation_env.policies.nash.nash_gap`); not counted in the policy's
            wall time.
        n_uav: N of a scenario that draws N per reset (None: the scenario's one N, or the N
            that all ``seeds`` draw).
        options: the simulator's :class:`~uav_formation_env.sim_options.SimOptions` (None:
            numpy on the CPU); with torch, a policy whose ``accepts_tensors`` is true (the DMPC
            metaheuristics, either layout) gets the observations as tensors and acts on the
            device; any other gets them as numpy arrays. The records are numpy arrays either way.
    """
    if duration is not None:
        scenario = with_overrides(scenario, {"duration": float(duration)})
    seeds = [check_seed(s, f"seeds[{k}]") for k, s in enumerate(seeds)]
    if not seeds or None in seeds:
        raise ValueError("seeds must be a non-empty list of non-negative ints")
    if n_uav is None and scenario.scene is not None:
        drawn = seeds_by_n_uav(scenario, seeds)
        if len(drawn) > 1:
            raise ValueError(
                f"seeds draw different N ({sorted(drawn)}); one batch has one N: run them with "
                "run_episode_groups, or pass n_uav"
            )
        n_uav = next(iter(drawn))
    batch, n_steps = len(seeds), scenario.n_steps
    # evaluation's rule: every seed is flown to its end, collisions are counted, not ended on
    episodes = FormationEpisodes(
        scenario,
        batch,
        fly_on_after_collision=True,
        n_uav=n_uav,
        options=options,
    )
    policy = as_batch_policy(policy)
    tensors = episodes.sim.backend != "numpy" and policy.accepts_tensors
    sim, n_uav = episodes.sim, episodes.n_uav
    policy.reset(batch, seeds=seeds)  # stochastic policies: one stream per episode seed
    start = time.perf_counter()
    step = episodes.reset(seed=seeds)
    result, obs = step.result, step.observation

    def centre_min(z: Any) -> np.ndarray:
        distance = to_numpy(obstacle_distances(z[..., :3], sim.field))
        return distance.min(axis=1, initial=np.inf)

    recorder = _Recorder(centre_min)
    recorder.state(result)
    policy_seconds = np.zeros(n_steps)
    sim_seconds = np.zeros(n_steps)
    gaps: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    sim_seconds_reset = time.perf_counter() - start
    bar = None
    callback = progress if callable(progress) else None
    if progress is True:
        bar = tqdm(total=n_steps, desc=desc or policy_name or "episodes", unit="step")
    links = policy.needs_neighbour_index
    for k in range(n_steps):
        t0 = time.perf_counter()
        seen = obs if tensors else to_numpy(obs)
        # whose plans each UAV receives: communication metadata, not the observation
        index = step.neighbour_index
        extra = ((index if tensors or index is None else to_numpy(index)),) if links else ()
        actions = policy.act_batch(seen, *extra)
        if not tensors:
            actions = np.asarray(actions, dtype=float)
        t1 = time.perf_counter()
        if tuple(actions.shape) != (batch, n_uav, 3):
            raise ValueError(
                f"policy returned actions of shape {tuple(actions.shape)}, expected "
                f"{(batch, n_uav, 3)}"
            )
        if nash_gap:
            host_obs, host_actions = to_numpy(obs), to_numpy(actions)
            plans = policy_plans(policy, host_obs, host_actions, scenario)
            gap = measure_nash_gap(host_obs, scenario, plans)
            gaps.append((gap.gap, gap.cost, gap.in_box))
        t_sim = time.perf_counter()
        step = episodes.step(actions)
        result, obs = step.result, step.observation
        policy_seconds[k] = t1 - t0
        sim_seconds[k] = time.perf_counter() - t_sim
        recorder.state(result)
        recorder.step(step)
        if bar is not None:
            bar.update(1)
        elif callback is not None:
            callback(1)
    if bar is not None:
        bar.close()
    sim_seconds[0] += sim_seconds_reset
    triggered = j_pre = j_exec = None
    records = policy.records()
    if getattr(records, "triggered", None) is not None and len(records.triggered) == n_steps:
        triggered = np.asarray(records.triggered, dtype=bool)
        j_pre = np.asarray(records.j_pre, dtype=float)
        j_exec = np.asarray(records.j_exec, dtype=float)
    gap_arrays = [np.stack(a) for a in zip(*gaps)] if gaps else [None, None, None]
    topo = sim.topology
    return EpisodeBatch(
        scenario=scenario,
        seeds=seeds,
        policy_name=policy_name,
        t=np.arange(n_steps + 1) * scenario.dynamics.dt,
        **recorder.arrays(),
        activation_time=np.array(to_numpy(topo.activation_time), dtype=float),
        restore_time=np.array(to_numpy(topo.restore_time), dtype=float),
        case=np.array(to_numpy(topo.case), dtype=int),
        triggered=triggered,
        j_pre=j_pre,
        j_exec=j_exec,
        policy_seconds=policy_seconds,
        sim_seconds=sim_seconds,
        nash_gap=gap_arrays[0],
        nash_cost=gap_arrays[1],
        nash_in_box=gap_arrays[2],
        scenes=None if scenario.scene is None else list(sim.scenes),
    )


def run_episode_groups(
    scenario: Scenario,
    policy: BatchPolicy,
    seeds: Sequence[int],
    **options: Any,
) -> list[EpisodeBatch]:
    """:func:`run_episodes` per group of seeds that draw the same N (one group, one batch, for a
    scenario of one N), groups in ascending N; ``options`` are those of :func:`run_episodes`
    (a progress bar's label gets the group's N)."""
    groups = seeds_by_n_uav(scenario, [check_seed(s, f"seeds[{k}]") for k, s in enumerate(seeds)])
    if len(groups) == 1:
        return [run_episodes(scenario, policy, seeds, **options)]
    label = options.get("desc") or options.get("policy_name") or "episodes"
    batches = []
    for n_uav, group in groups.items():
        batches.append(
            run_episodes(
                scenario, policy, group, **{**options, "desc": f"{label}, N={n_uav}"}, n_uav=n_uav
            )
        )
    return batches


def policy_plans(
    policy: BatchPolicy, obs: np.ndarray, actions: np.ndarray, scenario: Scenario
) -> np.ndarray:
    """Every UAV's input sequence over the horizon after ``policy`` acted on ``obs``.

    A policy that broadcasts plans (the DMPC's ``plans``) gives them as they are. Any other
    policy's plan is its action ``a · u_max`` held over the horizon, clipped to the UAV's box
    ``|u_n| <= u_max - |estimate|`` (docs/model.md §1.5: the part of the actuator range the plant
    leaves
    to the formation input while the observer compensates).

    Returns:
        (B, N, H, 3) [m/s^2].
    """
    plans = as_batch_policy(policy).plans
    if isinstance(plans, np.ndarray) and plans.shape[:2] == actions.shape[:2]:
        return plans
    u_max, horizon = scenario.dynamics.u_max, scenario.cost.horizon
    half_width = input_half_width(decode_observations(obs, scenario.n_uav).estimate, u_max)
    held = np.clip(np.clip(actions, -1.0, 1.0) * u_max, -half_width, half_width)
    return np.repeat(held[:, :, None, :], horizon, axis=2)


class _Recorder:
    """The per-step records of an episode batch, on the host: the state after the reset and
    after every step, and every step's inputs, disturbance, cost and collisions."""

    def __init__(self, centre_min: Any) -> None:
        self.centre_min = centre_min
        self.states: list[tuple[np.ndarray, ...]] = []
        self.steps: list[tuple] = []

    def state(self, result: Any) -> None:
        self.states.append(_state_record(result, self.centre_min))

    def step(self, step: Any) -> None:
        """Records an :class:`~uav_formation_env.episode.EpisodeStep`."""
        result = step.result
        self.steps.append(
            (
                to_numpy(result.u_n),
                to_numpy(result.u_applied),
                to_numpy(result.disturbance),
                to_numpy(result.cost.total),
                {name: to_numpy(v) for name, v in result.cost.as_dict().items()},
                to_numpy(step.reward),
                to_numpy(result.collision),
            )
        )

    def arrays(self) -> dict[str, Any]:
        """The :class:`EpisodeBatch` fields of the records, stacked along time."""
        states = self.states
        u_n, u_applied, disturbance, stage, terms, reward, collision = zip(*self.steps)
        return {
            "z": np.stack([s[0] for s in states]),
            "reference_velocity": np.stack([s[1] for s in states]),
            "estimate": np.stack([s[2] for s in states]),
            "groups": np.stack([s[3] for s in states]),
            "min_separation": np.stack([s[4] for s in states]),
            "obstacle_surface": np.stack([s[5] for s in states]),
            "obstacle_center": np.stack([s[6] for s in states]),
            "u_n": np.stack(u_n),
            "u_applied": np.stack(u_applied),
            "disturbance": np.stack(disturbance),
            "stage_cost": np.stack(stage),
            "cost_terms": {name: np.stack([t[name] for t in terms]) for name in terms[0]},
            "reward": np.stack(reward),
            "collision": np.stack(collision),
        }


def _state_record(result, centre_min) -> tuple[np.ndarray, ...]:
    """The recorded state fields of a step, as numpy arrays (copies off a device)."""
    return (
        to_numpy(result.z),
        to_numpy(result.reference_velocity),
        to_numpy(result.estimate),
        to_numpy(result.groups),
        to_numpy(result.min_separation),
        to_numpy(result.obstacle_distance),
        centre_min(result.z),
    )
