"""``uav_formation_v0``: PettingZoo ParallelEnv of UAV formation under disturbances and obstacles.

A thin view of the episode layer (:class:`~uav_formation_env.episode.FormationEpisodes`) with one
scenario copy: it holds no physics, no formula and no episode rule. Agents ``uav_0 … uav_{N-1}``
(paper: N = 5). Each agent acts with a normalised acceleration command ``a ∈ [-1, 1]^3``
(``u_n = a · u_max``), observes ``19 + 7 (N - 1)`` float32 values (47 for N = 5), laid out as
the slot table of :mod:`uav_formation_env.core.observation`, and is rewarded with minus the
stage cost of its own game cost J_i (through ``episode.reward``'s transform). Invalid actions
raise ``ValueError`` naming the agent and leave the environment as it was.

docs/env.md is the reference: the reward's formula, termination and truncation, the training
options, every info key, distributions over N and the global state.
"""

from __future__ import annotations

import copy

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from uav_formation_env.config import Scenario
from uav_formation_env.core.training_reward import TERMS
from uav_formation_env.episode import (
    FormationEpisodes,
    StepResult,
    observation_bounds,
    validate_actions,
)
from uav_formation_env.scenes import draw_scene, n_uav_range
from uav_formation_env.seeding import check_seed

RENDER_MODES = ["rgb_array", "human"]
REWARD_TERMS = tuple(f"reward_{name}" for name in TERMS)  # info keys of the training reward
INFO_MODES = ("numeric", "rich")


def agent_names(n_uav: int) -> list[str]:
    """``["uav_0", …, "uav_{N-1}"]``."""
    return [f"uav_{i}" for i in range(n_uav)]


def _common(d, e, ref, g, o, s, c, p, v, pen) -> dict:
    """The info entries both info modes share, for one agent."""
    return {
        "disturbance": d,
        "disturbance_estimate": e,
        "reference_velocity": ref,
        "group": g,
        "obstacle_distance": o,
        "min_separation": s,
        "collision": c,
        "position": p,
        "velocity": v,
        "penalty": pen,
    }


class UAVFormationParallelEnv(ParallelEnv):
    """PettingZoo ParallelEnv of the scenario (see the module docstring for the contract).

    Args:
        scenario: a validated scenario.
        render_mode: None, "rgb_array" or "human".
        info_mode: ``"numeric"`` (every info value a number or a fixed-shape array, as TorchRL
            and RLlib need) or ``"rich"`` (cost terms as a dict, neighbours as agent names).
    """

    metadata = {
        "name": "uav_formation_v0",
        "render_modes": RENDER_MODES,
        "render_fps": 5,
        "is_parallelizable": True,
    }

    def __init__(
        self, scenario: Scenario, render_mode: str | None = None, info_mode: str = "numeric"
    ) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}"
            )
        if info_mode not in INFO_MODES:
            raise ValueError(f"info_mode must be one of {INFO_MODES}, got {info_mode!r}")
        self.info_mode = info_mode
        self.scenario = scenario
        self.render_mode = render_mode
        # a distribution over N draws N per reset: the agents of a reset are the first N of
        # possible_agents (PettingZoo's contract), and the env rebuilds its one-copy episode
        # layer whenever N changes
        low, high = (
            (scenario.n_uav, scenario.n_uav) if scenario.scene is None else n_uav_range(scenario)
        )
        if low != high and scenario.observation.kind != "local":
            raise ValueError(
                f"scenario {scenario.name!r} draws N in {low}..{high} per reset: its "
                "observation.kind must be 'local' (the full layout's size depends on N)"
            )
        self.episodes = FormationEpisodes(scenario, batch_size=1, n_uav=low)
        self.sim = self.episodes.sim
        self.possible_agents = agent_names(high)
        self._names = agent_names(low)  # the agents of the current episode
        self._seed_stream: np.random.Generator | None = None  # seeds of unseeded resets
        self.agents: list[str] = []
        obs_low, obs_high = observation_bounds(scenario, low)
        obs_space = spaces.Box(obs_low, obs_high, dtype=np.float32)
        act_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: act_space for a in self.possible_agents}
        n = high  # a smaller N's state is padded with zeros to this size
        self.state_space = spaces.Box(
            -np.inf, np.inf, shape=(12 * n + 1 + n * n,), dtype=np.float32
        )
        self._result: StepResult | None = None
        self._renderer = None
        self._neighbour_cache: dict[bytes, tuple[tuple[str, ...], ...]] = {}

    def observation_space(self, agent: str) -> spaces.Box:
        try:
            return self.observation_spaces[agent]
        except (KeyError, TypeError):
            raise KeyError(self._unknown_agent(agent)) from None

    def action_space(self, agent: str) -> spaces.Box:
        try:
            return self.action_spaces[agent]
        except (KeyError, TypeError):
            raise KeyError(self._unknown_agent(agent)) from None

    def _unknown_agent(self, agent: object) -> str:
        return (
            f"unknown agent {agent!r}: this scenario has the agents "
            f"{self.possible_agents[0]}..{self.possible_agents[-1]}"
        )

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """Start an episode; ``seed`` (None or an int >= 0) makes it (and later unseeded resets)
        reproducible."""
        seed = check_seed(seed)
        if self.scenario.scene is not None:
            seed = self._scene_for(seed)
        self._result = self.episodes.reset(seed=None if seed is None else [seed]).result
        self.agents = list(self._names)
        if self._renderer is not None:
            self._renderer.reset()
        obs, infos = self._observations(), self._infos(np.zeros(len(self._names)))
        if self.scenario.episode.reward == "train":  # the step's keys, so that specs stay fixed
            for info in infos.values():
                info.update(dict.fromkeys(REWARD_TERMS, 0.0))
        if len(self._names) < len(self.possible_agents):
            self._pad_absent(obs, infos)
        return obs, infos

    def _pad_absent(self, obs: dict, infos: dict) -> None:
        """Entries for the possible agents this episode does not have (a distribution over N):
        a zero observation and an info of the same keys, zero-valued (``neighbours`` all False),
        so that consumers with one fixed agent set (TorchRL's ``PettingZooWrapper(...,
        use_mask=True)``) can build their specs from any reset; such agents are not in
        ``agents`` and never act."""
        template = infos[self._names[0]]
        absent = {
            key: np.zeros_like(value) if isinstance(value, np.ndarray) else type(value)()
            for key, value in template.items()
        }
        zero = np.zeros(self.observation_spaces[self.possible_agents[0]].shape, np.float32)
        for agent in self.possible_agents[len(self._names) :]:
            obs[agent] = zero.copy()
            infos[agent] = {key: copy.copy(value) for key, value in absent.items()}

    def _scene_for(self, seed: int | None) -> int | None:
        """For a distribution over N: the seed of this reset (an unseeded reset takes the next
        seed of the stream the last seed started, or fresh entropy) and an episode layer of the
        N that seed draws. Other scenarios: the seed as it is."""
        low, high = n_uav_range(self.scenario)
        if low == high:
            return seed
        if seed is not None:
            self._seed_stream = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
        else:
            stream = self._seed_stream or np.random.default_rng()
            seed = int(stream.integers(2**63))
        n_uav = draw_scene(self.scenario, np.random.default_rng(seed)).n_uav
        if n_uav != self.episodes.n_uav:
            self.episodes = FormationEpisodes(self.scenario, batch_size=1, n_uav=n_uav)
            self.sim = self.episodes.sim
            self._names = agent_names(n_uav)
            self._neighbour_cache.clear()
        return seed

    def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance one control step δ with every live agent's normalised action."""
        if not self.agents:
            raise RuntimeError("the episode is over (or reset() was never called): call reset()")
        if len(self._names) < len(self.possible_agents) and isinstance(actions, dict):
            # the possible agents this episode does not have act on nothing (as TorchRL sends)
            absent = self.possible_agents[len(self._names) :]
            actions = {a: v for a, v in actions.items() if a not in absent}
        step = self.episodes.step_validated(validate_actions(actions, self.agents)[None])
        self._result = step.result
        penalty, total = step.penalty[0], step.cost[0]
        terminated, truncated = bool(step.terminated[0]), bool(step.truncated[0])
        obs = self._observations()
        infos = self._infos(penalty, total)
        if step.terms is not None:  # the training reward's terms, as reward_<term>
            for name, values in step.terms.items():
                for info, value in zip(infos.values(), values[0].tolist()):
                    info[f"reward_{name}"] = value
        rewards = dict(zip(self.agents, step.reward[0].tolist()))
        terminations = dict.fromkeys(self.agents, terminated)
        truncations = dict.fromkeys(self.agents, truncated)
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

    def _observations(self) -> dict[str, np.ndarray]:
        obs = self.episodes.observe()[0]
        return dict(zip(self._names, obs))  # row views, as obs[i]

    def _infos(self, penalty: np.ndarray, total: np.ndarray | None = None) -> dict[str, dict]:
        """Every agent's info dict; ``total`` is the (N,) stage cost if already summed."""
        r = self._result
        names = self._names
        # one conversion per quantity, then per-agent views: this runs every step
        if total is None:
            total = r.cost.total[0]
        total = total.tolist()
        cost_terms = r.cost.as_dict()
        z = r.z[0].copy()
        disturbance, estimate = r.disturbance[0].copy(), r.estimate[0].copy()
        reference = r.reference_velocity[0].copy()
        groups, collision = r.groups[0].tolist(), r.collision[0].tolist()
        obstacle, separation = r.obstacle_distance[0].tolist(), r.min_separation[0].tolist()
        penalty, t = penalty.tolist(), float(r.t[0])
        rows = (
            disturbance, estimate, reference, groups, obstacle, separation, collision,
            z[:, :3], z[:, 3:], penalty,
        )  # fmt: skip
        if self.info_mode == "rich":
            terms = {name: value[0].tolist() for name, value in cost_terms.items()}
            neighbours = self._neighbour_names(r.adjacency[0])
            own = [
                {
                    "cost_terms": {name: values[i] for name, values in terms.items()},
                    "neighbours": list(neighbours[i]),
                }
                for i in range(len(names))
            ]
            return {
                agent: {"J": j, **extra, **_common(*common), "t": t}
                for agent, j, extra, *common in zip(names, total, own, *rows)
            }
        # numeric: one dict per agent in one go, the six terms of CostTerms unpacked by name
        # (this runs every step: 2% of a B = 1 step less than merging per-agent dicts, measured
        # with callgrind); iterating the arrays makes the row views in C, cheaper than indexing
        f, e, m, v, s, ob = (value[0].tolist() for value in cost_terms.values())
        mask = r.adjacency[0] != 0
        if len(names) < len(self.possible_agents):  # one shape over every N: pad with False
            mask = np.pad(mask, ((0, 0), (0, len(self.possible_agents) - len(names))))
        return {
            agent: {
                "J": j,
                "cost_formation": cf,
                "cost_energy": ce,
                "cost_terminal": cm,
                "cost_velocity": cv,
                "cost_separation": cs,
                "cost_obstacle": co,
                "neighbours": nb,
                "disturbance": dist,
                "disturbance_estimate": est,
                "reference_velocity": ref,
                "group": g,
                "obstacle_distance": o,
                "min_separation": sep,
                "collision": c,
                "position": p,
                "velocity": vel,
                "penalty": pen,
                "t": t,
            }
            for agent, j, cf, ce, cm, cv, cs, co, nb, dist, est, ref, g, o, sep, c, p, vel, pen in (
                zip(names, total, f, e, m, v, s, ob, mask, *rows)
            )
        }

    def _neighbour_names(self, adjacency: np.ndarray) -> tuple[tuple[str, ...], ...]:
        """Names of the agents each agent receives from, for an (N, N) adjacency.

        Memoised per adjacency pattern: the topology takes a handful of values per scenario.
        """
        receives = adjacency != 0
        key = receives.tobytes()
        names = self._neighbour_cache.get(key)
        if names is None:
            agents = self._names
            names = tuple(
                tuple(agents[j] for j, flag in enumerate(row) if flag) for row in receives.tolist()
            )
            if len(self._neighbour_cache) >= 64:
                self._neighbour_cache.clear()
            self._neighbour_cache[key] = names
        return names

    @property
    def neighbour_index(self) -> np.ndarray | None:
        """(N, k) the agent index in each neighbour slot of the local observation (-1: absent),
        for policies that exchange plans with them (``NashDMPCPolicy.act(obs, neighbour_index)``);
        None with the full observation."""
        if self._result is None:
            raise RuntimeError("call reset() before neighbour_index")
        index = self.episodes.last.neighbour_index
        return None if index is None else index[0]

    def state(self) -> np.ndarray:
        """Global state (see the module docstring)."""
        if self._result is None:
            raise RuntimeError("call reset() before state()")
        state = self.episodes.state()[0]
        size = self.state_space.shape[0]
        if state.size < size:  # a smaller N of a distribution over N
            state = np.concatenate((state, np.zeros(size - state.size, dtype=state.dtype)))
        return state

    def render(self) -> np.ndarray | None:
        """Top view: an RGB array ("rgb_array") or a window ("human")."""
        if self.render_mode is None:
            return None
        if self._result is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from uav_formation_env.render.top_view import TopViewRenderer

            self._renderer = TopViewRenderer(self.scenario)
        r = self._result
        frame = self._renderer.frame(
            r.z[0, :, :3],
            r.reference_velocity[0],
            r.adjacency[0],
            r.groups[0],
            float(r.t[0]),
            r.collision[0],
        )
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
