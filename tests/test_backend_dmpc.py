"""The reference DMPC policy on torch (policies/, core/cost/horizon.py, core/cost/quadratic.py).

numpy is the reference. On torch (float64; the CPU in CI, CUDA when present) the minimisers, the
horizon cost with its quadratic form and separation screen, and a closed-loop NashDMPCPolicy
flying the paper scenario through the torch episode layer must give the numpy numbers, given the
same seeds: the random numbers are drawn from the same numpy generators on both backends.
"""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env.config import CostConfig
from uav_formation_env.config_io import paper_scenario
from uav_formation_env.core.array_api import to_numpy
from uav_formation_env.core.cost import prepare_horizon_cost
from uav_formation_env.core.dynamics import rollout
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.dmpc import NashDMPCPolicy
from uav_formation_env.policies.optimizers import (
    LFPIOConfig,
    PIOConfig,
    PSOConfig,
    RowStreams,
    minimise,
)
from uav_formation_env.sim_options import SimOptions

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
OFFSETS = np.asarray(paper_scenario().formation.offsets, dtype=float)


def on(x, device):
    return torch.as_tensor(np.array(x), device=device)


def shifted_bowl(x):
    """Σ (x - target)² over the (5, 3) point, with a different target per problem."""
    target = np.linspace(-0.8, 0.8, 60).reshape(4, 5, 3)
    if isinstance(x, torch.Tensor):
        target = on(target, x.device)
    diff = x - target[:, None]
    return (diff * diff).sum(-1).sum(-1)


def streams(seed: int) -> RowStreams:
    return RowStreams([np.random.default_rng(seed), np.random.default_rng(seed + 1)], [1, 3])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("config", [PIOConfig(), LFPIOConfig(), PSOConfig()], ids=type)
def test_minimisers_on_torch_equal_numpy(config, device: str) -> None:
    """Same per-copy streams, same box: the same best points and costs, and the result stays a
    tensor on the device of the warm start."""
    x0 = np.zeros((4, 5, 3))
    expected = minimise(shifted_bowl, x0, -0.5, 0.7, streams(3), config, compiled=False)
    got = minimise(shifted_bowl, on(x0, device), -0.5, 0.7, streams(3), config)
    assert isinstance(got.x, torch.Tensor) and got.x.device.type == device
    np.testing.assert_allclose(to_numpy(got.x), expected.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(to_numpy(got.cost), expected.cost, rtol=1e-12)
    assert got.n_evals == expected.n_evals
    assert (expected.cost < expected.initial_cost).all()  # it did minimise


def test_compiled_kernels_refuse_tensors() -> None:
    with pytest.raises(ValueError, match="numpy arrays only"):
        minimise(
            shifted_bowl,
            torch.zeros(4, 5, 3, dtype=torch.float64),
            -1,
            1,
            np.random.default_rng(0),
            LFPIOConfig(),
            compiled=True,
        )


@pytest.mark.parametrize("device", DEVICES)
def test_population_cost_with_close_uavs_on_torch_equals_numpy(device: str) -> None:
    """The quadratic form, its separation screen and the triggered problems taken out of order
    (SeparationCost.take) give the numpy numbers on torch."""
    rng = np.random.default_rng(7)
    b, n, h = 2, 5, 5
    z0 = np.concatenate(
        (800.0 + rng.normal(0, 4, (b, n, 3)), 20.0 + rng.normal(0, 2, (b, n, 3))), axis=-1
    )
    z0[0, 4, :3] += 300.0  # its pairs are screened out
    neighbours = rollout(z0[:, :, None], rng.uniform(-5, 5, (b, n, 1, h, 3)), 0.2)[:, :, 0]
    reference = rng.normal(0, 20, (b, n, h + 1, 3))
    adjacency = (rng.random((b, n, n)) < 0.6).astype(float)
    half = rng.uniform(0.5, 5.0, (b, n, 3))
    candidates = rng.uniform(-1, 1, (b, n, 40, h, 3)) * half[:, :, None, None, :]
    args = (z0, neighbours, reference, adjacency)
    expected = prepare_horizon_cost(*args, OFFSETS, CostConfig(), 0.2)
    got = prepare_horizon_cost(*(on(a, device) for a in args), OFFSETS, CostConfig(), 0.2)
    quad_np, quad = expected.quadratic(half), got.quadratic(on(half, device))
    assert quad_np.separation is not None and 0 < quad_np.separation.rows.size < b * n
    np.testing.assert_array_equal(to_numpy(quad.separation.rows), quad_np.separation.rows)
    total = expected.terms(candidates).total
    assert total.shape == (b, n, 40)
    np.testing.assert_allclose(
        to_numpy(quad.total(on(candidates, device))), total, rtol=1e-10, atol=1e-8
    )
    index = np.array([9, 0, 4, 3])
    flat = candidates.reshape(b * n, 40, h, 3)[index][None]
    taken = to_numpy(quad.take(on(index, device)).total(on(flat, device)))
    np.testing.assert_allclose(taken[0], total.reshape(b * n, 40)[index], rtol=1e-10, atol=1e-8)


def fly(
    backend: str,
    optimizer: str,
    seeds: list[int],
    steps: int,
    device: str = "cpu",
    random: str = "generator",
):
    scenario = paper_scenario()
    options = SimOptions(backend=backend, device=device if backend == "torch" else None)
    episodes = FormationEpisodes(scenario, len(seeds), options=options)
    policy = NashDMPCPolicy(scenario, optimizer, random=random)
    policy.reset(len(seeds), seeds=seeds)
    step = episodes.reset(seed=seeds)
    states, actions = [], []
    for _ in range(steps):
        action = policy.act_batch(step.observation)
        actions.append(to_numpy(action).copy())
        step = episodes.step(action)
        states.append(to_numpy(step.result.z).copy())
    return np.stack(states), np.stack(actions), policy


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("optimizer", ["lfpio", "pio"])
def test_closed_loop_dmpc_on_torch_equals_numpy(optimizer: str, device: str) -> None:
    """Two seeds in one batch, 25 steps of the paper scenario: the torch episode layer flown by
    the torch policy gives the numpy states, actions and records (to rounding: the numpy LFPIO
    may run the compiled kernels)."""
    z_np, u_np, policy_np = fly("numpy", optimizer, [3, 8], 25)
    z, u, policy = fly("torch", optimizer, [3, 8], 25, device)
    assert isinstance(policy._plans, torch.Tensor) and policy._plans.device.type == device
    np.testing.assert_allclose(u, u_np, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(z, z_np, rtol=1e-9, atol=1e-9)
    records, records_np = policy.records(), policy_np.records()
    np.testing.assert_array_equal(records.triggered, records_np.triggered)
    assert records.triggered.sum() > 0  # the optimiser ran
    np.testing.assert_array_equal(records.evaluations, records_np.evaluations)
    np.testing.assert_allclose(records.j_exec, records_np.j_exec, rtol=1e-9)
    assert isinstance(policy.plans, np.ndarray)


def test_numpy_only_solvers_refuse_tensor_observations() -> None:
    """'exact' is numpy-only: a tensor observation gets a message that
    says so, and the policy still acts on numpy afterwards."""
    scenario = paper_scenario()
    episodes = FormationEpisodes(scenario, 1, options=SimOptions(backend="torch"))
    policy = NashDMPCPolicy(scenario, "exact")
    obs = episodes.reset(seed=[0]).observation
    with pytest.raises(ValueError, match="numpy only"):
        policy.act_batch(obs)
    action = policy.act_batch(to_numpy(obs))
    assert action.shape == (1, 5, 3) and np.isfinite(action).all()


def test_runner_on_torch_records_the_numpy_episode() -> None:
    """run_episodes on torch: the DMPC acts on tensors, the heuristic (numpy-only) gets numpy
    observations, and both record the numpy run's episode as numpy arrays."""
    from uav_formation_env.config_io import with_overrides
    from uav_formation_env.evaluation import make_policy, run_episodes

    scenario = with_overrides(paper_scenario(), {"duration": 3.0})
    for name in ("pio", "heuristic"):
        policy = make_policy(name, scenario)
        numpy_run = run_episodes(scenario, make_policy(name, scenario), [4, 9])
        torch_run = run_episodes(scenario, policy, [4, 9], options=SimOptions("torch", "cpu"))
        # the DMPC acted on the device (its plans are tensors); the heuristic has no plans
        assert isinstance(getattr(policy, "_plans", None), torch.Tensor) == (name == "pio")
        for field in ("z", "stage_cost", "u_n", "estimate", "obstacle_center"):
            got = getattr(torch_run, field)
            assert isinstance(got, np.ndarray), field
            np.testing.assert_allclose(got, getattr(numpy_run, field), rtol=1e-9, atol=1e-9)
        if name == "pio":
            np.testing.assert_array_equal(torch_run.triggered, numpy_run.triggered)
            assert torch_run.triggered.any()


@pytest.mark.parametrize("device", DEVICES)
def test_counter_draws_fly_the_same_on_numpy_and_torch(device: str) -> None:
    """random="counter": the numbers are computed on the device (no host generators), and the
    torch episode equals the numpy one to rounding."""
    z_np, u_np, policy_np = fly("numpy", "lfpio", [3, 8], 25, random="counter")
    z, u, policy = fly("torch", "lfpio", [3, 8], 25, device, random="counter")
    np.testing.assert_allclose(u, u_np, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(z, z_np, rtol=1e-9, atol=1e-9)
    assert policy.records().triggered.sum() > 0
    # and they are not the generator's numbers
    _, u_generator, _ = fly("numpy", "lfpio", [3, 8], 25)
    assert np.abs(u_generator - u_np).max() > 1e-3


def test_counter_draws_do_not_depend_on_the_batch() -> None:
    """A seed flies the same alone and beside other seeds (each UAV's numbers are keyed by its
    episode's seeds, itself and the step), with PIO, LFPIO and PSO."""
    for optimizer in ("pio", "lfpio", "pso"):
        _, together, _ = fly("numpy", optimizer, [11, 5, 2], 15, random="counter")
        _, alone, _ = fly("numpy", optimizer, [5], 15, random="counter")
        np.testing.assert_array_equal(alone[:, 0], together[:, 1])


def test_unknown_random_source_is_named() -> None:
    with pytest.raises(ValueError, match="random must be one of"):
        NashDMPCPolicy(paper_scenario(), "lfpio", random="philox")


def test_readme_gpu_reproduction_command_runs_on_the_cpu(tmp_path) -> None:
    """The README's GPU command, with --device cpu, one seed and two steps."""
    from uav_formation_env.cli import main

    argv = ["reproduce", "--seeds", "1", "--duration", "0.4", "--backend", "torch"]
    argv += ["--device", "cpu", "--random-source", "counter", "--game-variants", "none"]
    assert main([*argv, "--quiet", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "table2.csv").is_file()


def _fly_lfpio(
    scenario, backend: str, device: str, steps: int
) -> tuple[list, list, NashDMPCPolicy]:
    """LFPIO over ``steps`` steps of seeds 3 and 8 on ``backend``: its actions and the states
    after each step (copies, in the backend's library) and the policy."""
    options = SimOptions(backend=backend, device=device if backend == "torch" else None)
    episodes = FormationEpisodes(scenario, 2, options=options)
    policy = NashDMPCPolicy(scenario, "lfpio")
    policy.reset(2, seeds=[3, 8])
    step = episodes.reset(seed=[3, 8])
    actions, states = [], []
    for _ in range(steps):
        action = policy.act_batch(step.observation, step.neighbour_index)
        step = episodes.step(action)
        actions.append(action.clone() if isinstance(action, torch.Tensor) else action.copy())
        states.append(to_numpy(step.result.z).copy())
    return actions, states, policy


@pytest.mark.parametrize("device", DEVICES)
def test_local_layout_dmpc_on_torch_equals_numpy(device: str) -> None:
    """The N-independent local observation: the torch policy decodes its slots and exchanges
    plans through the neighbour index on the device, and flies the numpy episode."""
    from uav_formation_env.config_io import with_overrides

    scenario = with_overrides(paper_scenario(), {"observation.kind": "local"})
    runs = []
    for backend in ("numpy", "torch"):
        actions, states, policy = _fly_lfpio(scenario, backend, device, 15)
        assert isinstance(actions[-1], torch.Tensor) == (backend == "torch")
        assert policy.records().triggered.sum() > 0
        runs.append(np.stack([to_numpy(z) for z in states]))
    np.testing.assert_allclose(runs[1], runs[0], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("kind", ["full", "local"])
def test_dmpc_with_the_obstacle_term_on_torch_equals_numpy(device: str, kind: str) -> None:
    """J_i's obstacle term (an obstacle 110 m ahead of the start, 2 s lookahead): the torch
    policy decodes the obstacles of either layout, screens and evaluates the term on the device,
    and flies the numpy episode; the term changes the actions (it acts)."""
    from uav_formation_env.config_io import with_overrides

    scenario = with_overrides(
        paper_scenario(),
        {
            "observation.kind": kind,
            "avoidance.obstacles": [{"center": [110.0, 0.0], "radius": 20.0}],
            "cost.obstacle": 100.0,
            "cost.obstacle_lookahead": 10,
        },
    )
    without = with_overrides(scenario, {"cost.obstacle": 0.0})
    runs = []
    for backend, sc in (("numpy", scenario), ("torch", scenario), ("numpy", without)):
        actions, _, _ = _fly_lfpio(sc, backend, device, 10)
        runs.append(np.stack([to_numpy(u) for u in actions]))
    np.testing.assert_allclose(runs[1], runs[0], rtol=1e-9, atol=1e-11)
    assert np.abs(runs[2] - runs[0]).max() > 0.1  # the term acted
