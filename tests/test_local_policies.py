"""The reference DMPC and the heuristic acting from the N-independent local observation: the same
J_i and actions as from the full layout where both see everything (paper, N = 5), plans exchanged
through the slot index, and evaluation over a distribution of N (seeds grouped by drawn N)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.core.local_observation import decode_local_observations
from uav_formation_env.core.observation import decode_observations
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation import (
    make_policy,
    mission_of,
    run_episode_groups,
    run_episodes,
    summarise_groups,
)
from uav_formation_env.policies.broadcast import horizon_problems
from uav_formation_env.scenes import draw_scene

PAPER = resolve_scenario("paper")
PAPER_LOCAL = with_overrides(PAPER, {"observation.kind": "local"})
SWARM = with_overrides(resolve_scenario("random_swarm"), {"duration": 40.0})


def flown_episodes(seed: int = 3, steps: int = 40):
    """The paper and its local-layout twin flown ``steps`` steps by the heuristic, same seed."""
    out = []
    for scenario in (PAPER, PAPER_LOCAL):
        episodes = FormationEpisodes(scenario, 2)
        step = episodes.reset(seed=[seed, seed + 1])
        policy = make_policy("heuristic", scenario)
        for _ in range(steps):
            step = episodes.step(policy.act_batch(step.observation))
        out.append(step)
    return out


def test_local_and_full_layouts_give_the_same_horizon_cost():
    # At N = 5 with k = 4 every other UAV has a slot, so J_i from the local layout is J_i from
    # the full one, up to the float32 rounding of the two encodings.
    full, local = flown_episodes()
    np.testing.assert_allclose(full.result.z, local.result.z, atol=1e-4)  # the same flight
    plans = np.random.default_rng(0).normal(size=(2, 5, 5, 3))
    config = PAPER_LOCAL.observation
    decoded_local = decode_local_observations(
        local.observation,
        config.neighbours,
        config.obstacles,
        config.nearest,
        neighbour_index=local.neighbour_index,
    )
    ours = horizon_problems(decoded_local, plans, PAPER_LOCAL)
    theirs = horizon_problems(decode_observations(full.observation, 5), plans, PAPER)
    candidates = np.random.default_rng(1).normal(size=(2, 5, 7, 5, 3)) * 2.0
    j_local = ours.cost.terms(candidates)
    j_full = theirs.cost.terms(candidates)
    for name in ("formation", "energy", "terminal", "velocity", "separation"):
        np.testing.assert_allclose(
            getattr(j_local, name), getattr(j_full, name), rtol=2e-5, atol=1e-3, err_msg=name
        )
    assert (j_full.formation > 1.0).all()  # the check is not vacuous
    np.testing.assert_allclose(ours.half_width, theirs.half_width, rtol=1e-6)


def test_plans_are_exchanged_through_the_slot_index():
    # the formation term reads the plans of the UAVs in the receiver's slots: permuting which
    # UAV sits in which slot must change J_i, and giving a UAV's plan to another must too
    _, local = flown_episodes()
    config = PAPER_LOCAL.observation
    obs, index = local.observation, local.neighbour_index

    def j_of(plans, neighbour_index):
        decoded = decode_local_observations(
            obs, config.neighbours, config.obstacles, config.nearest,
            neighbour_index=neighbour_index,
        )  # fmt: skip
        problems = horizon_problems(decoded, plans, PAPER_LOCAL)
        return problems.cost.terms(np.zeros((2, 5, 1, 5, 3))).total[..., 0]

    plans = np.random.default_rng(2).normal(size=(2, 5, 5, 3))
    base = j_of(plans, index)
    swapped = plans.copy()
    swapped[:, [0, 1]] = plans[:, [1, 0]]
    assert not np.allclose(j_of(swapped, index), base)
    assert not np.allclose(j_of(plans, np.roll(index, 1, axis=-1)), base)
    # only UAV 0 broadcasts a non-zero plan: exactly the receivers with UAV 0 in a slot flagged
    # h_ij = 1 see J_i change
    zero = np.zeros_like(plans)
    only_0 = zero.copy()
    only_0[:, 0] = plans[:, 0]
    decoded = decode_local_observations(obs, config.neighbours, config.obstacles, config.nearest)
    receives_0 = ((index == 0) & decoded.neighbour & decoded.slot_present).any(axis=-1)
    assert receives_0.any() and not receives_0.all()
    changed = ~np.isclose(j_of(only_0, index), j_of(zero, index), rtol=1e-12, atol=0)
    np.testing.assert_array_equal(changed, receives_0)


def test_heuristic_acts_alike_on_both_layouts():
    full, local = flown_episodes()
    ours = make_policy("heuristic", PAPER_LOCAL).act_batch(local.observation)
    theirs = make_policy("heuristic", PAPER).act_batch(full.observation)
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    assert np.abs(theirs).max() > 0.05


def test_dmpc_on_the_local_layout_needs_the_slot_index():
    policy = make_policy("lfpio", PAPER_LOCAL, seed=0)
    episodes = FormationEpisodes(PAPER_LOCAL, 1)
    step = episodes.reset(seed=0)
    with pytest.raises(ValueError, match="neighbour_index is required"):
        policy.act_batch(step.observation)
    with pytest.raises(ValueError, match="neighbour_index must be integers of shape"):
        policy.act_batch(step.observation, step.neighbour_index[..., :2])
    actions = policy.act_batch(step.observation, step.neighbour_index)  # still usable
    assert actions.shape == (1, 5, 3) and np.isfinite(actions).all()


def test_dmpc_local_matches_full_on_the_paper_scene():
    # the same seed from both layouts: LFPIO's random streams are the same and so are J_i up to
    # float32 rounding, so the first seconds fly the same to well under a metre
    # (the policy is built for the 10 s episode: the observation carries t / duration)
    short = [replace(sc, duration=10.0) for sc in (PAPER, PAPER_LOCAL)]
    runs = [run_episodes(sc, make_policy("lfpio", sc, seed=1), [4]) for sc in short]
    np.testing.assert_allclose(runs[0].z[..., :3], runs[1].z[..., :3], atol=0.5)
    assert runs[0].triggered.sum() > 0


def test_random_swarm_runs_grouped_by_drawn_n():
    seeds = [0, 1, 2, 3]
    batches = run_episode_groups(SWARM, make_policy("heuristic", SWARM), seeds)
    drawn = {s: draw_scene(SWARM, np.random.default_rng(s)).n_uav for s in seeds}
    assert len(batches) == len(set(drawn.values())) > 1
    for batch in batches:
        assert {drawn[s] for s in batch.seeds} == {batch.z.shape[2]}
    summary = summarise_groups(batches)
    order = [s for batch in batches for s in batch.seeds]
    assert sorted(order) == seeds and summary["seeds"] == order
    assert summary["n_uav_per_seed"] == [drawn[s] for s in order]
    completed = sum(int(mission_of(b).completed.sum()) for b in batches)
    assert summary["mission"]["completed"] == completed
    assert summary["mission"]["episodes"] == len(seeds)
    per_seed = [c for b in batches for c in b.stage_cost.sum(axis=0).mean(axis=1)]
    np.testing.assert_allclose(summary["realised_cost_per_seed"], per_seed)
    terms = summary["realised_cost_terms"]
    assert sum(terms.values()) == pytest.approx(summary["realised_cost_mean"], rel=1e-12)
    assert set(summary["groups"]) == {str(n) for n in drawn.values()}
    n_steps = batches[0].n_steps
    policy_seconds = sum(b.policy_seconds.sum() for b in batches)
    assert summary["policy_time_per_step_s"] == pytest.approx(policy_seconds / n_steps)


def test_seeds_of_one_drawn_n_run_without_naming_it():
    # `uav-formation evaluate --scenario random_swarm --seeds 1` and `uav-formation run`: the
    # batch takes the N its seeds draw; seeds of several N are refused with the way out
    policy = make_policy("heuristic", SWARM)
    n_uav = {s: draw_scene(SWARM, np.random.default_rng(s)).n_uav for s in (0, 1, 4)}
    (group,) = run_episode_groups(SWARM, policy, [4])
    alone = run_episodes(SWARM, policy, [4])
    assert group.z.shape[2] == alone.z.shape[2] == n_uav[4]
    np.testing.assert_array_equal(group.z, alone.z)
    assert n_uav[0] != n_uav[1]
    with pytest.raises(ValueError, match=r"seeds draw different N .*run_episode_groups"):
        run_episodes(SWARM, policy, [0, 1])


def test_a_seed_flies_the_same_alone_and_in_its_group():
    policy = make_policy("lfpio", SWARM, seed=0)
    groups = run_episode_groups(SWARM, policy, [0, 1, 2, 3])
    assert max(len(batch.seeds) for batch in groups) > 1  # some seed shares its batch
    for batch in groups:
        seed = batch.seeds[-1]
        alone = run_episodes(
            SWARM, make_policy("lfpio", SWARM, seed=0), [seed], n_uav=batch.z.shape[2]
        )
        np.testing.assert_array_equal(alone.z[:, 0], batch.z[:, -1])
