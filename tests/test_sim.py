"""FormationSim: determinism, batching, the heuristic flying the paper scenario, input checks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from uav_formation_env.cli import main as cli_main
from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.core.cost import stage_cost
from uav_formation_env.core.topology import obstacle_distances
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.sim import NOISE_BLOCK, FormationSim


def fly(sim: FormationSim, steps: int, seed=0, record=False):
    result = sim.reset(seed=seed)
    trace = [result]
    for _ in range(steps):
        u = consensus_pd(
            result.z, result.reference_velocity, result.adjacency, sim.offsets, sim.u_max
        )
        result = sim.step(u)
        if record:
            trace.append(result)
    return trace if record else result


def test_same_seed_bit_identical_and_different_seed_differs():
    scenario = paper_scenario()
    a = fly(FormationSim(scenario), 150, seed=3, record=True)
    b = fly(FormationSim(scenario), 150, seed=3, record=True)
    c = fly(FormationSim(scenario), 150, seed=4, record=True)
    for ra, rb in zip(a, b):
        assert np.array_equal(ra.z, rb.z)
        assert np.array_equal(ra.disturbance, rb.disturbance)
        assert np.array_equal(ra.estimate, rb.estimate)
        assert np.array_equal(ra.cost.total, rb.cost.total)
    assert not np.array_equal(a[-1].z, c[-1].z)


def test_batch_copies_equal_single_simulations_across_noise_blocks_and_partial_reset():
    scenario = paper_scenario()
    batch = FormationSim(scenario, batch_size=3)
    singles = [FormationSim(scenario) for _ in range(3)]
    rng = np.random.default_rng(0)
    rb = batch.reset(seed=10)
    rs = [s.reset(seed=10 + b) for b, s in enumerate(singles)]
    steps = NOISE_BLOCK + 30  # crosses a refill of the noise block
    for k in range(steps):
        u = rng.uniform(-6, 6, size=(3, scenario.n_uav, 3))  # also exercises clipping
        if k == 60:  # copy 1 restarts mid-run with its own seed
            rb = batch.reset(seed=[99], mask=np.array([False, True, False]))
            rs[1] = singles[1].reset(seed=99)
        rb = batch.step(u)
        rs = [s.step(u[b : b + 1]) for b, s in enumerate(singles)]
        for b in range(3):
            assert np.array_equal(rb.z[b], rs[b].z[0])
            assert np.array_equal(rb.cost.total[b], rs[b].cost.total[0])
    assert rb.step.tolist() == [steps, steps - 60, steps]


def test_step_validates_input_and_keeps_state():
    sim = FormationSim(paper_scenario())
    with pytest.raises(RuntimeError, match="reset"):
        sim.step(np.zeros((1, 5, 3)))
    before = sim.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        sim.step(np.zeros((5, 3)))
    bad = np.zeros((1, 5, 3))
    bad[0, 2, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        sim.step(bad)
    assert np.array_equal(sim.last.z, before.z) and sim.last.step[0] == 0
    after = sim.step(np.zeros((1, 5, 3)))
    assert after.step[0] == 1


def test_inputs_clipped_and_compensation_applied():
    scenario = paper_scenario()
    sim = FormationSim(scenario)
    sim.reset(seed=0)
    for _ in range(30):
        result = sim.step(np.full((1, 5, 3), 100.0))
    u_max = scenario.dynamics.u_max
    assert np.all(result.u_n == u_max)
    np.testing.assert_allclose(result.u_applied, np.clip(result.u_n + result.u_d, -u_max, u_max))
    assert np.abs(result.u_d).max() > 0  # the observer estimate is fed back
    off = FormationSim(with_overrides(scenario, {"observer.enabled": False}))
    off.reset(seed=0)
    r = off.step(np.ones((1, 5, 3)))
    assert np.all(r.u_d == 0) and np.all(r.estimate == 0)


def test_reward_terms_are_the_cost_module_stage_cost():
    scenario = paper_scenario()
    sim = FormationSim(scenario)
    result = fly(sim, 57)
    expected = stage_cost(
        result.z,
        result.u_n,
        result.reference_velocity,
        result.adjacency,
        sim.offsets,
        scenario.cost,
    )
    np.testing.assert_array_equal(result.cost.total, expected.total)


@pytest.mark.slow
def test_heuristic_flies_the_paper_scenario_past_both_obstacles():
    scenario = paper_scenario()
    seeds = 6
    sim = FormationSim(scenario, batch_size=seeds)
    result = sim.reset(seed=0)
    min_centre = np.full(seeds, np.inf)
    split_at_first = np.zeros(seeds, dtype=bool)
    activations = np.zeros((seeds, 2), dtype=int)
    restores = np.zeros((seeds, 2), dtype=int)
    collisions = 0
    for _ in range(scenario.n_steps):
        u = consensus_pd(
            result.z, result.reference_velocity, result.adjacency, sim.offsets, sim.u_max
        )
        result = sim.step(u)
        centre = obstacle_distances(result.z[..., :3], scenario.avoidance)  # (B, N, O)
        min_centre = np.minimum(min_centre, centre.min(axis=(1, 2)))
        activations += result.activated
        restores += result.restored
        split_at_first |= result.activated[:, 0] & (result.groups.max(axis=1) == 1)
        collisions += int(result.collision.sum())
    assert result.truncated.all() and result.step[0] == scenario.n_steps
    assert (activations == 1).all() and (restores == 1).all()  # both obstacles met and left
    assert split_at_first.all()  # case 2 at O1
    assert min_centre.min() >= 30.0, min_centre
    assert collisions == 0
    # the formation ends heading -y as the schedule asks, close to it
    np.testing.assert_allclose(result.z[..., 3:].mean(axis=1), [[0, -20, 0]] * seeds, atol=0.5)


def test_cli_run_writes_png_csv_and_summary(tmp_path):
    assert cli_main(["run", "--out", str(tmp_path), "--seed", "1", "--quiet"]) == 0
    assert (tmp_path / "trajectories.png").stat().st_size > 10_000
    lines = (tmp_path / "trajectory.csv").read_text().splitlines()
    assert lines[0].startswith("seed,step,t,uav,x,y,z,vx,vy,vz")
    assert len(lines) == 1 + 1000 * 5
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["min_obstacle_surface_distance_m"] > 0
    assert summary["collisions"] == 0
    assert [e["event"] for e in summary["events"]] == ["activate", "restore"] * 2
