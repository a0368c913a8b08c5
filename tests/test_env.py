"""The contract of ``uav_formation_v0`` (PettingZoo parallel and AEC) and its Gymnasium view.

PettingZoo's own checkers over a matrix of scenario variants, state checks, rendering, the reward
and info contract, episode ends, the observation layout and every documented bad input.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo.test import (
    api_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    state_test,
)

import uav_formation_env
from uav_formation_env import GYM_ID, env, parallel_env
from uav_formation_env.config_io import save_scenario, with_overrides
from uav_formation_env.core.observation import decode_observations, observation_dim
from uav_formation_env.scenarios import make_scenario

RICH_INFO_TYPES = {
    "J": float,
    "cost_terms": dict,
    "disturbance": np.ndarray,
    "disturbance_estimate": np.ndarray,
    "reference_velocity": np.ndarray,
    "group": int,
    "neighbours": list,
    "obstacle_distance": float,
    "min_separation": float,
    "collision": bool,
    "position": np.ndarray,
    "velocity": np.ndarray,
    "penalty": float,
    "t": float,
}
COST_TERMS = {"formation", "energy", "terminal", "velocity", "separation", "obstacle"}
# numeric infos (the default): cost terms as flat keys, neighbours as an (N,) bool mask
INFO_TYPES = {
    **{
        key: kind
        for key, kind in RICH_INFO_TYPES.items()
        if key not in ("cost_terms", "neighbours")
    },
    **{f"cost_{term}": float for term in COST_TERMS},
    "neighbours": np.ndarray,
}
VECTOR_INFOS = ("disturbance", "disturbance_estimate", "reference_velocity", "position", "velocity")

# (n_uav, obstacles, observer, collision_mode): observer on/off, obstacles none/paper/random,
# collision none/penalty/terminate and N = 3, 5, 8 all appear.
MATRIX = [
    (5, "paper", True, "none"),
    (5, "paper", False, "none"),
    (5, "none", True, "penalty"),
    (5, "random", True, "terminate"),
    (5, "random", False, "none"),
    (3, "none", False, "none"),
    (3, "paper", True, "terminate"),
    (3, "random", False, "penalty"),
    (8, "paper", True, "penalty"),
    (8, "none", True, "none"),
    (8, "random", False, "terminate"),
    (8, "paper", False, "none"),
]
MATRIX_DURATION = 20.0  # [s] = 100 steps: reaches the paper's first obstacle, ends in the checkers
MATRIX_CYCLES = 120  # more than one episode's steps, so every checker sees the truncation
MATRIX_IDS = ["-".join(str(x) for x in combo) for combo in MATRIX]


def matrix_scenario(n_uav, obstacles, observer, collision_mode):
    return make_scenario(
        n_uav=n_uav,
        obstacles=obstacles,
        observer=observer,
        collision_mode=collision_mode,
        seed=n_uav,
        duration=MATRIX_DURATION,
    )


def random_actions(agents, rng: np.random.Generator, scale: float = 1.0) -> dict:
    return {a: rng.uniform(-scale, scale, 3).astype(np.float32) for a in agents}


def names(n_uav: int) -> list[str]:
    return [f"uav_{i}" for i in range(n_uav)]


def cost_terms(info: dict) -> dict[str, float]:
    """The named cost terms of an info, numeric (``cost_<term>``) or rich (``cost_terms``)."""
    if "cost_terms" in info:
        return info["cost_terms"]
    return {key[5:]: value for key, value in info.items() if key.startswith("cost_")}


def neighbour_names(info: dict, n_uav: int) -> list[str]:
    """The agents an agent receives from: the numeric info's mask or the rich info's names."""
    value = info["neighbours"]
    if isinstance(value, np.ndarray):
        assert value.shape == (n_uav,) and value.dtype == bool
        return [names(n_uav)[j] for j in np.flatnonzero(value)]
    return value


def check_infos(infos: dict, n_uav: int) -> None:
    assert set(infos) == set(names(n_uav))
    for agent, info in infos.items():
        types = RICH_INFO_TYPES if "cost_terms" in info else INFO_TYPES
        assert set(info) == set(types), agent
        for key, kind in types.items():
            assert isinstance(info[key], kind), (agent, key, type(info[key]))
        for key in VECTOR_INFOS:
            assert info[key].shape == (3,), (agent, key)
            assert np.isfinite(info[key]).all(), (agent, key)
        terms = cost_terms(info)
        assert set(terms) == COST_TERMS
        assert all(isinstance(v, float) for v in terms.values())
        assert info["J"] == pytest.approx(sum(terms.values()), rel=1e-12, abs=1e-9)
        assert terms["terminal"] == 0.0  # a stage has no terminal term
        assert np.isfinite(info["J"]) and info["J"] >= 0.0
        assert set(neighbour_names(info, n_uav)) <= set(names(n_uav)) - {agent}
        assert np.isfinite(info["min_separation"]) and info["min_separation"] >= 0.0
        assert not np.isnan(info["obstacle_distance"])  # +inf without obstacles


def check_state_layout(state: np.ndarray, infos: dict, n_uav: int) -> None:
    """positions / 100, velocities / 20, references / 20, estimates / 0.5, t / T, adjacency."""
    blocks = (
        ("position", 100.0, 1e-4),
        ("velocity", 20.0, 1e-5),
        ("reference_velocity", 20.0, 1e-5),
        ("disturbance_estimate", 0.5, 1e-7),
    )
    for k, (key, scale, atol) in enumerate(blocks):
        part = state[3 * n_uav * k : 3 * n_uav * (k + 1)].astype(float) * scale
        expected = np.stack([infos[a][key] for a in names(n_uav)]).ravel()
        np.testing.assert_allclose(part, expected, rtol=1e-6, atol=atol, err_msg=key)
    adjacency = state[12 * n_uav + 1 :].reshape(n_uav, n_uav)
    for i, agent in enumerate(names(n_uav)):
        expected = [names(n_uav)[j] for j in np.flatnonzero(adjacency[i])]
        assert neighbour_names(infos[agent], n_uav) == expected


# ---------------------------------------------------------------------------- the checker matrix
@pytest.mark.parametrize("combo", MATRIX, ids=MATRIX_IDS)
def test_pettingzoo_checkers_on_matrix(combo):
    scenario = matrix_scenario(*combo)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # advisory checker warnings (e.g. infinite state bounds)
        parallel_api_test(parallel_env(scenario=scenario), num_cycles=MATRIX_CYCLES)
        parallel_seed_test(lambda: parallel_env(scenario=scenario), num_cycles=MATRIX_CYCLES)
        api_test(env(scenario=scenario), num_cycles=MATRIX_CYCLES)
        state_test(env(scenario=scenario), parallel_env(scenario=scenario), num_cycles=10)


@pytest.mark.parametrize("combo", MATRIX, ids=MATRIX_IDS)
def test_state_and_step_contract_on_matrix(combo):
    n_uav, _, _, mode = combo
    scenario = matrix_scenario(*combo)
    penalty = scenario.collision.penalty
    n_states = 12 * n_uav + 1 + n_uav * n_uav
    envs = [parallel_env(scenario=scenario) for _ in range(2)]
    first = envs[0]
    with pytest.raises(RuntimeError):
        first.state()  # before reset
    assert first.state_space.shape == (n_states,)
    for e in envs:
        obs, infos = e.reset(seed=7)
    check_infos(infos, n_uav)
    state = first.state()
    assert state.shape == (n_states,) and state.dtype == np.float32
    assert first.state_space.contains(state)
    assert np.array_equal(state, envs[1].state())
    # state layout: positions / 100 m, velocities / 20 m/s first; time fraction; adjacency last
    check_state_layout(state, infos, n_uav)
    assert state[12 * n_uav] == 0.0

    rng = np.random.default_rng(sum(map(hash, map(str, combo))) % 2**32)
    steps = 0
    while first.agents:
        actions = random_actions(first.agents, rng)
        obs, rewards, terms, truncs, infos = first.step(actions)
        obs2, rewards2, *_ = envs[1].step(actions)
        steps += 1
        new_state = first.state()
        assert first.state_space.contains(new_state)
        assert np.isfinite(new_state).all()
        assert not np.array_equal(new_state, state), "state() did not change after a step"
        assert np.array_equal(new_state, envs[1].state()), "state() not deterministic for a seed"
        assert new_state[12 * n_uav] == pytest.approx(steps * 0.2 / scenario.duration)
        check_state_layout(new_state, infos, n_uav)
        state = new_state
        check_infos(infos, n_uav)
        for agent in names(n_uav):
            assert np.array_equal(obs[agent], obs2[agent])
            assert rewards[agent] == rewards2[agent]
            assert obs[agent].dtype == np.float32
            assert first.observation_space(agent).contains(obs[agent])
            info = infos[agent]
            assert np.isfinite(rewards[agent])
            assert info["t"] == pytest.approx(steps * 0.2)
            expected_penalty = penalty if (mode == "penalty" and info["collision"]) else 0.0
            assert info["penalty"] == expected_penalty
            assert rewards[agent] == -(info["J"] + info["penalty"])
            if mode != "penalty":
                assert rewards[agent] == -info["J"]
            # energy term: r ||u_n||^2 with u_n = action * u_max
            u_n = actions[agent].astype(float) * scenario.dynamics.u_max
            assert cost_terms(info)["energy"] == pytest.approx(
                scenario.cost.r * float(u_n @ u_n), rel=1e-12
            )
        collided = any(infos[a]["collision"] for a in names(n_uav))
        terminated = mode == "terminate" and collided
        assert all(terms[a] == terminated for a in names(n_uav))
        assert all(truncs[a] == (steps == scenario.n_steps and not terminated) for a in terms)
    assert steps == scenario.n_steps or (mode == "terminate" and any(terms.values()))


# ---------------------------------------------------------------------------- rendering
def test_render_test_and_frame():
    import matplotlib

    matplotlib.use("Agg")  # "human" mode of render_test must not open windows
    scenario = make_scenario(duration=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg: "FigureCanvasAgg is non-interactive"
        render_test(lambda render_mode=None: env(scenario=scenario, render_mode=render_mode))

    e = parallel_env(scenario=scenario, render_mode="rgb_array")
    with pytest.raises(RuntimeError):
        e.render()  # before reset
    e.reset(seed=0)
    frame = e.render()
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert min(frame.shape[:2]) >= 16
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10  # not blank
    e.step(random_actions(e.agents, np.random.default_rng(0)))
    second = e.render()
    assert second.shape == frame.shape and second.dtype == np.uint8
    e.close()

    plain = parallel_env(scenario=scenario)
    plain.reset(seed=0)
    assert plain.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        parallel_env(scenario=scenario, render_mode="ansi")


# ---------------------------------------------------------------------------- metadata and spaces
@pytest.mark.parametrize("n_uav", [3, 5, 8])
def test_metadata_agents_and_spaces(n_uav):
    e = parallel_env(scenario=make_scenario(n_uav=n_uav))
    assert e.metadata["name"] == "uav_formation_v0"
    assert set(e.metadata["render_modes"]) == {"rgb_array", "human"}
    assert e.possible_agents == names(n_uav)
    assert e.agents == []
    e.reset(seed=0)
    assert e.agents == names(n_uav)
    for agent in e.possible_agents:
        assert e.observation_space(agent) is e.observation_space(agent)
        assert e.action_space(agent) is e.action_space(agent)
        obs_space, act_space = e.observation_space(agent), e.action_space(agent)
        assert isinstance(obs_space, spaces.Box) and isinstance(act_space, spaces.Box)
        assert obs_space.shape == (observation_dim(n_uav),) == (19 + 7 * (n_uav - 1),)
        assert obs_space.dtype == np.float32 and act_space.dtype == np.float32
        assert act_space.shape == (3,)
        assert np.all(act_space.low == -1.0) and np.all(act_space.high == 1.0)
    aec = env(scenario=make_scenario(n_uav=n_uav))
    assert aec.metadata["name"] == "uav_formation_v0"
    assert aec.possible_agents == names(n_uav)


def test_paper_defaults():
    e = parallel_env()
    obs, _ = e.reset(seed=0)
    assert e.scenario.n_uav == 5 and e.scenario.n_steps == 1000
    assert all(o.shape == (47,) for o in obs.values())  # 19 + 7 * 4


def test_docstring_observation_size_for_paper():
    from uav_formation_env.envs import parallel

    stated = re.search(r"\((\d+) for N = 5\)", parallel.__doc__)
    assert stated is not None
    assert int(stated.group(1)) == observation_dim(5)


# ------------------------------------------------------------------------ rewards and collisions
def test_reward_is_minus_j_without_collision_mode():
    """reward = -J_i, and J_i is the stage cost of the state AFTER the step with the APPLIED
    formation input ``u_n = a · u_max``, recomputed here from ``core.cost.stage_cost`` (a reward
    from the state before the step, or from ``a`` unscaled, fails the second check)."""
    from uav_formation_env.core.cost import stage_cost

    e = parallel_env()
    e.reset(seed=3)
    rng = np.random.default_rng(3)
    sc, agents = e.scenario, e.possible_agents
    offsets = np.asarray(sc.formation.offsets, dtype=float)
    for _ in range(50):
        actions = random_actions(e.agents, rng)
        _, rewards, _, _, infos = e.step(actions)
        for agent in agents:
            assert rewards[agent] == -infos[agent]["J"]
            assert infos[agent]["penalty"] == 0.0

        def stacked(key: str, infos=infos) -> np.ndarray:
            return np.stack([np.asarray(infos[a][key], dtype=float) for a in agents])[None]

        z = np.concatenate((stacked("position"), stacked("velocity")), axis=-1)
        u_n = np.stack([np.asarray(actions[a], dtype=float) for a in agents])[None]
        u_n = u_n * sc.dynamics.u_max  # the actions are inside [-1, 1]: nothing is clipped
        expected = stage_cost(
            z,
            u_n,
            stacked("reference_velocity"),
            stacked("neighbours"),
            offsets,
            sc.cost,
        ).total[0]
        np.testing.assert_allclose([rewards[a] for a in agents], -expected, rtol=1e-12)


def drive_together(e, rng: np.random.Generator, max_steps: int = 200):
    """Steer uav_0 onto uav_1 (PD on their relative state), others random; yield each step."""
    _, infos = e.reset(seed=0)  # seed 0: every UAV starts > 14 m from the others
    assert min(info["min_separation"] for info in infos.values()) > 10.0
    u_max = e.scenario.dynamics.u_max
    for _ in range(max_steps):
        rel_p = infos["uav_1"]["position"] - infos["uav_0"]["position"]
        rel_v = infos["uav_1"]["velocity"] - infos["uav_0"]["velocity"]
        actions = random_actions(e.agents, rng, scale=0.05)
        actions["uav_1"] = np.zeros(3, dtype=np.float32)
        actions["uav_0"] = np.clip((0.5 * rel_p + 1.4 * rel_v) / u_max, -1, 1)
        result = e.step(actions)
        infos = result[4]
        yield actions, result


def test_penalty_mode_charges_colliding_agents_only():
    e = parallel_env(scenario=make_scenario(collision_mode="penalty", obstacles="none"))
    penalty = e.scenario.collision.penalty
    seen = False
    for _, (_, rewards, terms, truncs, infos) in drive_together(e, np.random.default_rng(0)):
        for agent in e.possible_agents:
            info = infos[agent]
            assert rewards[agent] == -(info["J"] + info["penalty"])
            assert info["penalty"] == (penalty if info["collision"] else 0.0)
            assert info["collision"] == (info["min_separation"] < 2.0)  # no obstacles here
        assert not any(terms.values()) and not any(truncs.values())
        if infos["uav_0"]["collision"]:
            assert infos["uav_1"]["collision"]
            assert infos["uav_0"]["min_separation"] < e.scenario.collision.uav_distance
            assert rewards["uav_0"] == -(infos["uav_0"]["J"] + penalty)
            others = [infos[a] for a in ("uav_2", "uav_3", "uav_4")]
            assert not any(info["collision"] for info in others)
            assert all(info["penalty"] == 0.0 for info in others)
            assert rewards["uav_2"] == -infos["uav_2"]["J"]
            seen = True
            break
    assert seen, "uav_0 never reached uav_1"


def tight_box(mode: str, duration: float = 4.0):
    """UAVs start within a 0.5 m box: closer than collision.uav_distance = 2 m."""
    return parallel_env(
        scenario=make_scenario(collision_mode=mode, obstacles="none", duration=duration),
        initial__position_low=(0.0, 0.0, 0.0),
        initial__position_high=(0.5, 0.5, 0.0),
        initial__min_spacing=0.0,  # no minimum spacing: start in a collision on purpose
    )


def test_penalty_mode_forced_collision_from_start():
    e = tight_box("penalty")
    _, infos = e.reset(seed=0)
    assert all(info["collision"] for info in infos.values())
    zero = {a: np.zeros(3, dtype=np.float32) for a in e.agents}
    _, rewards, terms, _, infos = e.step(zero)
    for agent in e.possible_agents:
        assert infos[agent]["collision"]
        assert infos[agent]["penalty"] == 1000.0
        assert rewards[agent] == -(infos[agent]["J"] + 1000.0)
        assert not terms[agent]
    assert e.agents == e.possible_agents


def test_terminate_mode_forced_collision_ends_episode_for_all():
    e = tight_box("terminate")
    e.reset(seed=0)
    zero = {a: np.zeros(3, dtype=np.float32) for a in e.agents}
    obs, rewards, terms, truncs, infos = e.step(zero)
    assert terms == dict.fromkeys(e.possible_agents, True)
    assert truncs == dict.fromkeys(e.possible_agents, False)
    assert e.agents == []
    assert set(obs) == set(rewards) == set(infos) == set(e.possible_agents)
    for agent in e.possible_agents:
        assert rewards[agent] == -infos[agent]["J"]  # no penalty outside "penalty" mode
    with pytest.raises(RuntimeError, match="reset"):
        e.step(zero)
    e.reset(seed=1)
    assert e.agents == e.possible_agents


def test_terminate_mode_driven_collision_ends_episode():
    e = parallel_env(scenario=make_scenario(collision_mode="terminate", obstacles="none"))
    for _, (_, _, terms, truncs, infos) in drive_together(e, np.random.default_rng(0)):
        collided = any(info["collision"] for info in infos.values())
        assert all(v == collided for v in terms.values())
        if collided:
            assert not any(truncs.values())
            assert e.agents == []
            return
        assert e.agents == e.possible_agents
    pytest.fail("no collision happened")


@pytest.mark.parametrize("fast", [True, False])
def test_a_uav_within_the_obstacle_distance_of_a_surface_collides(fast: bool) -> None:
    """UAV 0 held 1.0 m outside O1's surface: a collision from collision.obstacle_distance 1.5 m,
    none at the paper's 0 (inside only), on the kernels' path and the batched one."""
    flags = []
    for distance in (0.0, 1.5):
        e = parallel_env("paper", collision__obstacle_distance=distance)
        e.reset(seed=0)
        if not fast:
            e.sim.fast_path = None
        obstacle = e.scenario.avoidance.obstacles[0]
        e.sim.z[0, 0, :2] = (obstacle.center[0] + obstacle.radius + 1.0, obstacle.center[1])
        e.sim.z[0, 0, 3:] = 0.0  # at rest: still 1.0 m out after the step
        zero = {a: np.zeros(3, dtype=np.float32) for a in e.agents}
        infos = e.step(zero)[4]
        flags.append(infos["uav_0"]["collision"])
        assert not infos["uav_1"]["collision"]
    assert flags == [False, True]


# ---------------------------------------------------------------------------- truncation
def test_truncation_at_duration_then_step_raises():
    e = parallel_env(scenario=make_scenario(duration=2.0))
    assert e.scenario.n_steps == 10
    with pytest.raises(RuntimeError, match="reset"):
        e.step({})  # never reset
    e.reset(seed=0)
    rng = np.random.default_rng(0)
    for k in range(1, 11):
        actions = random_actions(e.agents, rng)
        _, _, terms, truncs, infos = e.step(actions)
        assert not any(terms.values())
        assert all(v == (k == 10) for v in truncs.values())
        assert infos["uav_0"]["t"] == pytest.approx(0.2 * k)
    assert e.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        e.step(actions)
    obs, _ = e.reset(seed=0)
    assert e.agents == e.possible_agents and set(obs) == set(e.possible_agents)


def test_aec_view_truncates_and_removes_agents():
    e = env(scenario=make_scenario(duration=2.0))
    e.reset(seed=0)
    for agent in e.possible_agents:
        e.action_space(agent).seed(0)
    steps = 0
    for agent in e.agent_iter():
        _, reward, term, trunc, info = e.last()
        assert isinstance(reward, int | float) and np.isfinite(reward)
        action = None if (term or trunc) else e.action_space(agent).sample()
        e.step(action)
        steps += 1
    assert e.agents == []
    assert steps == 11 * 5  # 10 cycles of 5 actions, then 5 removals


# ------------------------------------------------------------------------ infos and observations
@pytest.mark.parametrize("info_mode", ["numeric", "rich"])
def test_info_keys_types_and_paper_neighbours(info_mode: str):
    e = parallel_env(info_mode=info_mode)
    _, infos = e.reset(seed=0)
    check_infos(infos, 5)
    assert ("cost_terms" in infos["uav_0"]) == (info_mode == "rich")
    assert neighbour_names(infos["uav_0"], 5) == ["uav_1", "uav_3", "uav_4"]
    adjacency = np.asarray(e.scenario.formation.adjacency)
    for i, agent in enumerate(e.possible_agents):
        expected = [f"uav_{j}" for j in np.flatnonzero(adjacency[i])]
        assert neighbour_names(infos[agent], 5) == expected
        assert infos[agent]["t"] == 0.0
        assert infos[agent]["group"] == 0
        assert infos[agent]["reference_velocity"].tolist() == [20.0, 0.0, 0.0]
        assert infos[agent]["velocity"].tolist() == [20.0, 0.0, 0.0]
        np.testing.assert_array_equal(infos[agent]["disturbance"], 0.0)
        # paper: obstacles at (300, 0) and (1050, 400), r = 30 m; start box x in [0, 40]
        p = infos[agent]["position"]
        expected = np.hypot(300.0 - p[0], 0.0 - p[1]) - 30.0
        assert infos[agent]["obstacle_distance"] == pytest.approx(expected)
    _, _, _, _, infos = e.step(random_actions(e.agents, np.random.default_rng(0)))
    check_infos(infos, 5)
    assert any(np.any(info["disturbance"] != 0.0) for info in infos.values())
    # without obstacles the distance is +inf
    _, infos = parallel_env(scenario=make_scenario(obstacles="none")).reset(seed=0)
    assert all(info["obstacle_distance"] == np.inf for info in infos.values())


@pytest.mark.parametrize("n_uav", [3, 5, 8])
def test_observation_decodes_to_infos(n_uav):
    e = parallel_env(scenario=make_scenario(n_uav=n_uav))
    obs, infos = e.reset(seed=n_uav)
    offsets = np.asarray(e.scenario.formation.offsets)
    rng = np.random.default_rng(n_uav)
    avoiding_seen = False
    for step in range(150):  # 30 s: past the paper's first obstacle at x = 300 m
        for i, agent in enumerate(e.possible_agents):
            decoded = decode_observations(obs[agent], n_uav)
            info = infos[agent]
            np.testing.assert_allclose(decoded.velocity, info["velocity"], rtol=2e-7, atol=1e-5)
            np.testing.assert_allclose(
                decoded.reference_velocity, info["reference_velocity"], rtol=2e-7, atol=1e-5
            )
            np.testing.assert_allclose(
                decoded.estimate, info["disturbance_estimate"], rtol=2e-7, atol=1e-6
            )
            assert decoded.time_fraction == pytest.approx(info["t"] / e.scenario.duration)
            others = [f"uav_{j}" for j in range(n_uav) if j != i]
            flags = [o for o, flag in zip(others, decoded.neighbour) if flag]
            assert flags == neighbour_names(info, n_uav)
            assert obs[agent][18] == pytest.approx(info["min_separation"] / 100.0, rel=1e-6)
            # paper obstacles: present flag and distance to the nearest surface / 100 m
            assert obs[agent][17] == 1.0
            assert obs[agent][16] == pytest.approx(info["obstacle_distance"] / 100.0, rel=1e-6)
            # relative formation error of the k-th other UAV: a_j - a_i with a = z - z^d
            a = [
                np.concatenate((infos[o]["position"], infos[o]["velocity"])) - offsets[j]
                for j, o in enumerate(e.possible_agents)
            ]
            expected = np.stack([a[j] - a[i] for j in range(n_uav) if j != i])
            np.testing.assert_allclose(
                decoded.relative_formation_error, expected, rtol=1e-6, atol=1e-4
            )
            avoiding_seen |= bool(decoded.avoiding)
        if step == 149:
            break
        obs, _, _, _, infos = e.step(random_actions(e.agents, rng))
    assert avoiding_seen, "no UAV followed an avoidance reference: the test missed the obstacle"


# ---------------------------------------------------------------------------- bad inputs
def good_actions(e) -> dict:
    return {a: np.zeros(3, dtype=np.float32) for a in e.agents}


def _unknown(a):
    a["uav_99"] = np.zeros(3)


def _missing(a):
    del a["uav_2"]


def _set(agent, value):
    def apply(a):
        a[agent] = value

    return apply


BAD_ACTIONS = {
    "unknown agent": (_unknown, "uav_99"),
    "missing agent": (_missing, "uav_2"),
    "shape (2,)": (_set("uav_1", np.zeros(2)), "uav_1"),
    "shape (3, 1)": (_set("uav_3", np.zeros((3, 1))), "uav_3"),
    "scalar": (_set("uav_0", 0.5), "uav_0"),
    "NaN": (_set("uav_4", np.array([0.0, np.nan, 0.0])), "uav_4"),
    "+inf": (_set("uav_2", np.array([np.inf, 0.0, 0.0])), "uav_2"),
    "-inf": (_set("uav_0", np.array([0.0, 0.0, -np.inf])), "uav_0"),
    "string": (_set("uav_1", "fast"), "uav_1"),
    "string list": (_set("uav_1", ["a", "b", "c"]), "uav_1"),
    "None": (_set("uav_3", None), "uav_3"),
}


@pytest.mark.parametrize("case", list(BAD_ACTIONS))
def test_bad_action_raises_and_env_keeps_working(case):
    spoil, agent = BAD_ACTIONS[case]
    e = parallel_env()
    reference = parallel_env()
    e.reset(seed=5)
    reference.reset(seed=5)
    rng = np.random.default_rng(5)
    first = random_actions(e.agents, rng)
    e.step(first)
    reference.step(first)
    bad = good_actions(e)
    spoil(bad)
    with pytest.raises(ValueError, match=agent):
        e.step(bad)
    assert int(e.sim.steps[0]) == 1  # the failed call did not advance the step counter
    assert e.agents == e.possible_agents
    second = random_actions(e.agents, rng)
    obs, rewards, _, _, infos = e.step(second)
    ref_obs, ref_rewards, _, _, ref_infos = reference.step(second)
    assert infos["uav_0"]["t"] == pytest.approx(0.4)
    for a in e.possible_agents:  # as if the bad call never happened
        assert np.array_equal(obs[a], ref_obs[a])
        assert rewards[a] == ref_rewards[a]


def test_non_dict_actions_raise():
    e = parallel_env()
    e.reset(seed=0)
    with pytest.raises(ValueError, match="dict"):
        e.step(np.zeros((5, 3)))
    e.step(good_actions(e))


def test_out_of_range_actions_are_clipped():
    envs = [parallel_env() for _ in range(2)]
    for e in envs:
        e.reset(seed=9)
    signs = np.random.default_rng(9).choice([-1.0, 1.0], size=(5, 3))
    big = {a: 10.0 * signs[i] for i, a in enumerate(envs[0].agents)}
    unit = {a: 1.0 * signs[i] for i, a in enumerate(envs[1].agents)}
    for _ in range(3):
        obs_big, rew_big, _, _, info_big = envs[0].step(big)
        obs_unit, rew_unit, _, _, info_unit = envs[1].step(unit)
        assert np.array_equal(envs[0].state(), envs[1].state())
        for a in envs[0].possible_agents:
            assert np.array_equal(obs_big[a], obs_unit[a])
            assert rew_big[a] == rew_unit[a]
            assert np.array_equal(info_big[a]["position"], info_unit[a]["position"])


def test_bad_overrides_and_scenarios_raise_naming_the_field():
    with pytest.raises(ValueError, match="no_such_field"):
        parallel_env(no_such_field=1)
    with pytest.raises(ValueError, match="observer.lambda2"):
        parallel_env(observer__lambda2=2.5)
    with pytest.raises(ValueError, match="lambda2"):
        parallel_env(lambda2=2.5)  # not a top-level field
    with pytest.raises(ValueError, match="observer.lambda2"):
        parallel_env(observer={"lambda2": 2.5})
    with pytest.raises(ValueError, match="observer.enabeld"):
        parallel_env(observer__enabeld=False)
    with pytest.raises(ValueError, match="collision.mode"):
        parallel_env(collision__mode="explode")
    with pytest.raises(ValueError, match="no_such_scenario"):
        parallel_env("no_such_scenario")
    with pytest.raises(ValueError, match="no_such_scenario"):
        env("no_such_scenario")
    e = parallel_env()  # still fine afterwards
    e.reset(seed=0)
    e.step(good_actions(e))


def test_overrides_flat_and_nested(tmp_path: Path):
    flat = parallel_env(observer__enabled=False)
    nested = parallel_env(observer={"enabled": False})
    assert flat.scenario.observer.enabled is False
    assert flat.scenario == nested.scenario
    assert flat.scenario.observer.lambda2 == 1.5  # other observer fields keep the paper's values
    rng = np.random.default_rng(1)
    for e in (flat, nested):
        e.reset(seed=1)
    for _ in range(5):
        actions = random_actions(flat.agents, rng)
        obs_f, _, _, _, infos = flat.step(actions)
        obs_n, *_ = nested.step(actions)
        for a in flat.possible_agents:
            assert np.array_equal(obs_f[a], obs_n[a])
            np.testing.assert_array_equal(infos[a]["disturbance_estimate"], 0.0)
            np.testing.assert_array_equal(obs_f[a][9:12], 0.0)
    dotted = parallel_env(duration=2.0, collision__mode="penalty")
    assert dotted.scenario.n_steps == 10 and dotted.scenario.collision.mode == "penalty"


def test_scenario_from_yaml_path(tmp_path: Path):
    scenario = make_scenario(n_uav=3, obstacles="random", seed=4, duration=2.0)
    path = tmp_path / "scenario.yaml"
    save_scenario(scenario, path)
    for spec in (path, str(path)):
        e = parallel_env(scenario=spec)
        assert e.scenario == scenario
        assert e.possible_agents == names(3)
        e.reset(seed=0)
        while e.agents:
            e.step(good_actions(e))
    overridden = parallel_env(scenario=str(path), collision__mode="terminate")
    assert overridden.scenario == with_overrides(scenario, {"collision.mode": "terminate"})
    with pytest.raises(ValueError):
        parallel_env(scenario=str(tmp_path / "missing.yaml"))


def test_named_scenarios():
    for name in ("paper", "open_field", "windy", "random_obstacles", "n3", "n8"):
        e = parallel_env(name)
        obs, _ = e.reset(seed=0)
        assert len(obs) == e.scenario.n_uav


# ---------------------------------------------------------------------------- Gymnasium view
def test_gymnasium_make_and_checkers():
    from gymnasium.utils.env_checker import check_env as gym_check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    assert GYM_ID == "uav_formation_env/Formation-v0"
    assert uav_formation_env.GYM_ID in gymnasium.registry
    gym_env = gymnasium.make(GYM_ID)
    assert gym_env.observation_space.shape == (5 * 47,)
    assert gym_env.action_space.shape == (15,)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym_check_env(gym_env.unwrapped)
        sb3_check_env(gym_env.unwrapped, warn=True)
        sb3_check_env(gymnasium.make(GYM_ID, scenario=make_scenario(n_uav=3)), warn=True)
    gym_env.close()


def test_gymnasium_view_matches_parallel_env():
    scenario = make_scenario(n_uav=3, duration=2.0, collision_mode="penalty")
    gym_env = gymnasium.make(GYM_ID, scenario=scenario).unwrapped
    par = parallel_env(scenario=scenario)
    obs, info = gym_env.reset(seed=2)
    par_obs, _ = par.reset(seed=2)
    assert isinstance(info, dict)
    assert np.array_equal(obs, np.concatenate([par_obs[a] for a in par.possible_agents]))
    rng = np.random.default_rng(2)
    for k in range(1, 11):
        action = rng.uniform(-1, 1, 9).astype(np.float32)
        obs, reward, term, trunc, info = gym_env.step(action)
        par_obs, par_rew, _, _, par_infos = par.step(
            {a: action[3 * i : 3 * i + 3] for i, a in enumerate(par.possible_agents)}
        )
        assert obs.dtype == np.float32 and gym_env.observation_space.contains(obs)
        assert np.array_equal(obs, np.concatenate([par_obs[a] for a in par.possible_agents]))
        assert reward == pytest.approx(np.mean(list(par_rew.values())), rel=1e-12)
        assert np.array_equal(info["J"], [par_infos[a]["J"] for a in par.possible_agents])
        assert info["collision"].shape == (3,) and info["t"] == pytest.approx(0.2 * k)
        assert term is False and trunc is (k == 10)


def test_gymnasium_bad_actions():
    gym_env = gymnasium.make(GYM_ID).unwrapped
    gym_env.reset(seed=0)
    for bad in (np.zeros(14), np.zeros((5, 3)), np.zeros(16)):
        with pytest.raises(ValueError, match="shape"):
            gym_env.step(bad)
    nan = np.zeros(15)
    nan[4] = np.nan
    with pytest.raises(ValueError, match="uav_1"):
        gym_env.step(nan)
    _, _, _, _, info = gym_env.step(np.zeros(15, dtype=np.float32))
    assert info["t"] == pytest.approx(0.2)
