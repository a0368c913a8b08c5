"""The episode layer: reward transforms, divergence, mission corridor, autoreset, fly-on rule."""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env import parallel_env
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation import make_policy, mission_metrics

PAPER = resolve_scenario("paper")


def scenario(**episode):
    return with_overrides(PAPER, {"episode": episode})


def test_default_reward_is_minus_the_stage_cost() -> None:
    episodes = FormationEpisodes(PAPER, 2)
    episodes.reset(seed=[0, 1])
    step = episodes.step(np.full((2, 5, 3), 0.3))
    np.testing.assert_array_equal(step.reward, -step.result.cost.total)
    assert (step.penalty == 0).all() and not step.done.any()


@pytest.mark.parametrize(
    ("reward", "scale", "expected"),
    [
        ("raw", 1.0, lambda j: -j),
        ("scaled", 250.0, lambda j: -j / 250.0),
        ("log1p", 100.0, lambda j: -np.log(1.0 + j / 100.0)),
    ],
)
def test_reward_transforms(reward: str, scale: float, expected) -> None:
    episodes = FormationEpisodes(scenario(reward=reward, reward_scale=scale), 1)
    reference = FormationEpisodes(PAPER, 1)
    episodes.reset(seed=3)
    reference.reset(seed=3)
    actions = np.random.default_rng(0).uniform(-1, 1, (1, 5, 3))
    step, raw = episodes.step(actions), reference.step(actions)
    np.testing.assert_array_equal(step.cost, raw.cost)  # the physics is the same
    np.testing.assert_allclose(step.reward, expected(raw.cost), rtol=1e-12)
    assert (raw.cost > 100).any()  # far from the formation: the transforms differ


def test_reward_includes_the_collision_penalty_before_the_transform() -> None:
    crowded = with_overrides(
        PAPER,
        {
            "collision": {"mode": "penalty", "penalty": 1000.0},
            "initial": {"position_high": [0.5, 0.5, 0.0], "position_low": [0, 0, 0]},
            "initial.min_spacing": 0.0,
            "episode": {"reward": "log1p", "reward_scale": 10.0},
        },
    )
    episodes = FormationEpisodes(crowded, 1)
    episodes.reset(seed=0)
    step = episodes.step(np.zeros((1, 5, 3)))
    assert step.result.collision.all()
    np.testing.assert_allclose(step.reward, -np.log1p((step.cost + 1000.0) / 10.0), rtol=1e-12)


def sideways(batch: int = 1, push: float = 1.0) -> np.ndarray:
    """Full lateral (+y) acceleration for every UAV: the formation leaves the route."""
    actions = np.zeros((batch, 5, 3))
    actions[..., 1] = push
    return actions


def test_corridor_terminates_when_the_centroid_leaves_it() -> None:
    width = 50.0
    episodes = FormationEpisodes(scenario(corridor_width=width), 1)
    first = episodes.reset(seed=0)
    states, t = [first.result.z], [0.0]
    for _ in range(200):
        step = episodes.step(sideways())
        states.append(step.result.z)
        t.append(float(step.result.t[0]))
        if step.done[0]:
            break
    assert step.terminated[0] and step.left_corridor[0] and not step.truncated[0]
    # the evaluation's route error (one definition) crosses the width at exactly this step
    z = np.stack(states)
    metrics = [
        mission_metrics(PAPER, np.array(t[: k + 1]), z[: k + 1], np.zeros((k, 1, 5), bool),
                        np.full((k + 1, 1, 5), 10.0)).route_error_max[0]
        for k in (len(t) - 2, len(t) - 1)
    ]  # fmt: skip
    assert metrics[0] <= width < metrics[1]


def test_corridor_off_by_default_and_flown_on_route_never_ends() -> None:
    episodes = FormationEpisodes(scenario(corridor_width=100.0), 2)
    episodes.reset(seed=[0, 1])
    policy = make_policy("heuristic", PAPER)
    step = episodes.last
    for _ in range(150):  # 30 s, through O1
        step = episodes.step(policy.act_batch(step.observation))
        assert not step.left_corridor.any()
    lax = FormationEpisodes(PAPER, 1)
    lax.reset(seed=0)
    for _ in range(100):
        assert not lax.step(sideways()).done.any()


def test_divergence_truncates_without_changing_the_reward() -> None:
    episodes = FormationEpisodes(scenario(max_velocity_error=10.0), 1)
    episodes.reset(seed=0)
    for _ in range(100):
        step = episodes.step(sideways())
        error = np.linalg.norm(step.result.z[..., 3:] - step.result.reference_velocity, axis=-1)
        assert step.diverged[0] == (error.max() > 10.0)
        if step.done[0]:
            break
    assert step.truncated[0] and step.diverged[0] and not step.terminated[0]
    np.testing.assert_array_equal(step.reward, -step.cost)
    formation = FormationEpisodes(scenario(max_formation_error=30.0), 1)
    formation.reset(seed=0)
    spread = np.zeros((1, 5, 3))
    spread[0, :, 1] = np.linspace(-1, 1, 5)  # fan the UAVs out sideways
    for _ in range(100):
        if formation.step(spread).truncated[0]:
            break
    assert formation.last.diverged[0]


def test_autoreset_resets_only_the_ended_copy_and_keeps_its_last_observation() -> None:
    episodes = FormationEpisodes(scenario(corridor_width=40.0), 2, autoreset=True)
    episodes.reset(seed=[5, 6])
    actions = np.zeros((2, 5, 3))
    actions[0] = sideways()[0]  # copy 0 leaves the corridor, copy 1 flies on
    for _ in range(200):
        step = episodes.step(actions)
        if step.done.any():
            break
    assert step.done.tolist() == [True, False]
    assert step.reset.tolist() == [True, False]
    assert step.final_observation is not None
    np.testing.assert_array_equal(step.observation[1], step.final_observation[1])
    assert step.observation[0, 0, 12] == 0.0  # t / duration of the fresh episode
    assert step.final_observation[0, 0, 12] > 0.0
    assert episodes.sim.steps.tolist()[0] == 0


def test_collision_terminates_unless_flying_on() -> None:
    crowded = with_overrides(
        PAPER,
        {
            "collision.mode": "terminate",
            "initial": {"position_high": [0.5, 0.5, 0.0], "position_low": [0, 0, 0]},
            "initial.min_spacing": 0.0,
        },
    )
    ends = FormationEpisodes(crowded, 1)
    ends.reset(seed=0)
    assert ends.step(np.zeros((1, 5, 3))).terminated[0]
    flies = FormationEpisodes(crowded, 1, fly_on_after_collision=True)
    flies.reset(seed=0)
    step = flies.step(np.zeros((1, 5, 3)))
    assert step.collided[0] and not step.done[0]


def test_parallel_env_takes_the_episode_options() -> None:
    env = parallel_env("paper", episode__corridor_width=50.0, episode__reward="log1p")
    env.reset(seed=0)
    steps = 0
    while env.agents:
        actions = {a: np.array([0.0, 1.0, 0.0], dtype=np.float32) for a in env.agents}
        _, rewards, terminations, truncations, infos = env.step(actions)
        steps += 1
        assert rewards["uav_0"] == pytest.approx(-np.log1p(infos["uav_0"]["J"]))
    assert terminations["uav_0"] and not truncations["uav_0"]
    assert steps < 100


def test_bad_actions_are_refused_by_the_layer() -> None:
    episodes = FormationEpisodes(PAPER, 2)
    episodes.reset(seed=0)
    bad = np.zeros((2, 5, 3))
    bad[1, 3, 0] = np.nan
    with pytest.raises(ValueError, match=r"copy 1, uav_3"):
        episodes.step(bad)
    with pytest.raises(ValueError, match=r"shape \(2, 5, 3\)"):
        episodes.step(np.zeros((5, 3)))
    assert episodes.step(np.zeros((2, 5, 3))).result.step.tolist() == [1, 1]


@pytest.mark.parametrize(
    ("field", "value", "pattern"),
    [
        ("reward", "log", "episode.reward"),
        ("reward_scale", 0.0, "episode.reward_scale"),
        ("corridor_width", -1.0, "episode.corridor_width"),
        ("max_velocity_error", -2.0, "episode.max_velocity_error"),
    ],
)
def test_episode_options_are_validated(field: str, value, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        scenario(**{field: value})


def fly_from_zero(seed: int, steps: int, then: np.ndarray) -> np.ndarray:
    """A copy flown from t = 0 by the consensus PD for ``steps`` steps, then by ``then`` (K, N, 3)
    normalised actions: its states after each of those K steps (K, N, 6)."""
    from uav_formation_env.policies.heuristic import consensus_pd
    from uav_formation_env.sim import FormationSim

    sim = FormationSim(PAPER, 1)
    sim.reset(seed=seed)
    for _ in range(steps):
        last = sim.last
        sim.step(consensus_pd(sim.z, last.reference_velocity, last.adjacency, sim.offsets, 5.0))
    return np.stack([sim.step(a[None] * 5.0).z[0] for a in then])


def test_staggered_start_continues_the_controllers_episode_exactly() -> None:
    episodes = FormationEpisodes(scenario(start="staggered"), 4)
    first = episodes.reset(seed=20)
    assert first.result.step.tolist() == [0, 250, 500, 750]
    np.testing.assert_allclose(first.observation[:, 0, 12], [0.0, 0.25, 0.5, 0.75])
    then = np.random.default_rng(0).uniform(-1, 1, (30, 4, 5, 3))
    states = np.stack([episodes.step(a).result.z for a in then])  # (30, 4, 5, 6)
    for b, start in enumerate([0, 250, 500, 750]):
        # copy b is seed 20 + b flown to its start by the controller, noise and all
        np.testing.assert_array_equal(states[:, b], fly_from_zero(20 + b, start, then[:, b]))
    # later resets start at t = 0 again
    assert episodes.reset(seed=20).result.step.tolist() == [0, 0, 0, 0]


def test_random_start_is_named_by_the_seed_alone() -> None:
    batch = FormationEpisodes(scenario(start="random"), 3)
    starts = batch.reset(seed=[7, 8, 9]).result.step
    assert len(set(starts.tolist())) == 3 and (starts < PAPER.n_steps).all()
    alone = FormationEpisodes(scenario(start="random"), 1).reset(seed=8)
    assert alone.result.step[0] == starts[1]
    np.testing.assert_array_equal(alone.result.z[0], batch.last.result.z[1])
    np.testing.assert_array_equal(alone.observation[0], batch.last.observation[1])


def test_random_start_on_autoreset_and_truncation_at_the_duration() -> None:
    episodes = FormationEpisodes(scenario(start="random"), 2, autoreset=True)
    first = episodes.reset(seed=[1, 2]).result.step.copy()
    remaining = PAPER.n_steps - first
    shortest = int(remaining.min())
    for _ in range(shortest):
        step = episodes.step(np.zeros((2, 5, 3)))
    ended = remaining == shortest
    assert step.truncated.tolist() == ended.tolist()  # the duration still ends the episode
    new_start = episodes.sim.steps[ended]
    assert (new_start < PAPER.n_steps).all()  # the next episode started somewhere else again


def test_leaving_the_corridor_costs_the_corridor_penalty() -> None:
    episodes = FormationEpisodes(scenario(corridor_width=50.0, corridor_penalty=1e6), 1)
    episodes.reset(seed=0)
    for _ in range(200):
        step = episodes.step(sideways())
        if step.done[0]:
            break
        assert (step.penalty == 0).all()
    assert step.left_corridor[0]
    np.testing.assert_array_equal(step.penalty, np.full((1, 5), 1e6))
    np.testing.assert_allclose(step.reward, -(step.cost + 1e6))


def test_the_step_pair_distances_are_reused_only_for_the_step_own_result():
    from uav_formation_env.core.cost.stage import pair_distances
    from uav_formation_env.episode import encode_observations

    # all pairs (swarm_20 senses within a radius: tests/test_proximity.py)
    scenario = with_overrides(resolve_scenario("swarm_20"), {"observation.sensing_radius": None})
    episodes = FormationEpisodes(scenario, 3)
    episodes.reset(seed=0)
    sim = episodes.sim
    step = episodes.step(np.random.default_rng(0).uniform(-1, 1, (3, 20, 3)))
    assert sim.pair_distances_of(step.result) is sim._pair_of[1]  # one pass this step
    # a result merged from two (partial reset) gets its own distances
    merged = sim.reset(seed=[7], mask=np.array([False, True, False]))
    shifted = type(merged)(**{**merged.__dict__, "z": merged.z + 1.0})
    assert sim.pair_distances_of(shifted) is not sim._pair_of[1]
    np.testing.assert_array_equal(
        sim.pair_distances_of(shifted), pair_distances(shifted.z[..., :3])
    )
    obs, index = encode_observations(sim, merged)
    sim._pair_of = (None, sim._pair_of[1])  # force the recomputation
    fresh, fresh_index = encode_observations(sim, merged)
    np.testing.assert_array_equal(obs, fresh)
    np.testing.assert_array_equal(index, fresh_index)
