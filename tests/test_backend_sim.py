"""A whole episode on the torch backend equals the numpy episode (issue 14, "Equality").

The numpy simulator is the reference. The torch simulator (float64; CPU in CI, CUDA when present)
gets the same inputs: each copy's numpy Generator draws the same scene, start and noise on both
backends, so every state, cost and output must agree to 1e-9 (relative), at every step.
"""

from __future__ import annotations

import warnings
from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from uav_formation_env.config_io import paper_scenario
from uav_formation_env.core.array_api import to_numpy
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.scenarios import random_fields_scenario, random_routes_scenario
from uav_formation_env.sim import FormationSim
from uav_formation_env.sim_options import SimOptions

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def assert_results_equal(expected, got, where: str) -> None:
    """Every array field of two StepResults (nested dataclasses too), to 1e-9 relative."""
    for f in fields(expected):
        a, b = getattr(expected, f.name), getattr(got, f.name)
        if is_dataclass(a):
            assert_results_equal(a, b, f"{where}.{f.name}")
            continue
        assert not isinstance(b, np.ndarray), f"{where}.{f.name} is a numpy array on torch"
        b = to_numpy(b)
        assert b.dtype == a.dtype, f"{where}.{f.name}: dtype {b.dtype} != {a.dtype}"
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9, err_msg=f"{where}.{f.name}")


def fly_both(scenario, device: str, steps: int, seeds=(0, 1), reset_at: int | None = None) -> int:
    """Fly numpy and torch copies with the numpy run's inputs; compare every step. At step
    ``reset_at`` copy 1 alone is reset (seed 99) in both. Returns the number of obstacle
    activations seen (the test must exercise the avoidance)."""
    batch = len(seeds)
    reference = FormationSim(scenario, batch_size=batch)
    candidate = FormationSim(scenario, batch, options=SimOptions("torch", device))
    expected, got = reference.reset(seed=list(seeds)), candidate.reset(seed=list(seeds))
    assert_results_equal(expected, got, "reset")
    activations = 0
    for step in range(steps):
        u = consensus_pd(
            expected.z,
            expected.reference_velocity,
            expected.adjacency,
            reference.offsets,
            reference.u_max,
        )
        expected, got = reference.step(u), candidate.step(torch.as_tensor(u, device=device))
        assert_results_equal(expected, got, f"step {step + 1}")
        if step + 1 == reset_at:
            mask = np.arange(batch) == 1
            expected = reference.reset(seed=[99], mask=mask)
            got = candidate.reset(seed=[99], mask=torch.as_tensor(mask, device=device))
            assert_results_equal(expected, got, f"partial reset after step {step + 1}")
            assert float(got.t[1]) == 0.0 and float(got.t[0]) > 0.0
        activations += int(expected.activated.sum())
    return activations


@pytest.mark.parametrize("device", DEVICES)
def test_paper_episode_equal_on_torch(device):
    scenario = paper_scenario()
    assert fly_both(scenario, device, scenario.n_steps) >= 4  # both obstacles, both copies


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("make", [random_fields_scenario, random_routes_scenario])
def test_drawn_scenes_equal_on_torch(make, device):
    """Per-copy obstacle fields, routes and disturbances; a partial reset in the middle."""
    assert fly_both(make(), device, 250, seeds=(3, 4, 5), reset_at=120) >= 1


def test_backend_and_device_are_checked():
    scenario = paper_scenario()
    with pytest.raises(ValueError, match="backend must be one of"):
        SimOptions(backend="jax")
    with pytest.raises(ValueError, match="runs on device 'cpu' only"):
        SimOptions(backend="numpy", device="cuda")
    with pytest.raises(ValueError, match="device must name a torch device"):
        SimOptions(backend="torch", device="moon")
    with pytest.raises(TypeError, match="options must be a SimOptions"):
        FormationSim(scenario, options="torch")


def fly_episodes(options: SimOptions, steps: int) -> list[list[np.ndarray]]:
    """The episode layer of the paper scenario, 3 copies with autoreset, zero actions (the
    formation flies straight into O1, so avoidance runs), as numpy per step: the observations,
    rewards, flags and the simulator's result and topology state."""
    episodes = FormationEpisodes(paper_scenario(), 3, autoreset=True, options=options)
    episodes.reset(seed=[1, 2, 3])
    zeros = torch.zeros((3, 5, 3), dtype=torch.float64)
    flown = []
    for _ in range(steps):
        step = episodes.step(zeros)
        arrays = [step.observation, step.reward, step.terminated, step.truncated]
        arrays += [getattr(step.result, f.name) for f in fields(step.result) if f.name != "cost"]
        arrays += [getattr(step.result.cost, f.name) for f in fields(step.result.cost)]
        topology = episodes.sim.topology
        arrays += [getattr(topology, f.name) for f in fields(topology)]
        flown.append([to_numpy(a).copy() for a in arrays])
    return flown


def test_compiled_step_equals_the_eager_one(monkeypatch) -> None:
    """SimOptions(compile=True): the whole step (the simulator's and the episode layer's)
    through torch.compile gives the eager numbers (to rounding) over 80 steps that include an
    avoidance, and over 10 steps with counter noise; where compilation fails, one warning each
    and the eager step."""
    from uav_formation_env.core import tracing

    eager = fly_episodes(SimOptions("torch"), 80)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # compiled, not the eager fallback
        compiled = fly_episodes(SimOptions("torch", compile=True), 80)
    avoiding = [k for k, step in enumerate(eager) if step[4 + 9].any()]  # result.avoiding
    assert avoiding, "no avoidance in the compared steps"
    # counter noise: drawn inside the compiled step
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        counter = fly_episodes(SimOptions("torch", compile=True, noise="counter"), 10)
    counter_eager = fly_episodes(SimOptions("torch", noise="counter"), 10)
    for name, (first, second) in {
        "": (eager, compiled),
        "counter": (counter_eager, counter),
    }.items():
        for k, (a, b) in enumerate(zip(first, second)):
            for x, y in zip(a, b):
                assert x.dtype == y.dtype
                message = f"{name} step {k}"
                np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12, err_msg=message)

    def broken(function):
        def fail(*args):
            raise RuntimeError("no compiler here")

        return fail

    monkeypatch.setattr(tracing, "torch_compiled", broken)
    with pytest.warns(RuntimeWarning, match="torch.compile of FormationSim._advance failed"):
        fallback = fly_episodes(SimOptions("torch", compile=True), 2)
    for x, y in zip(eager[1], fallback[1]):
        np.testing.assert_array_equal(y, x)
    with pytest.raises(ValueError, match="compile=True needs backend='torch'"):
        SimOptions(compile=True)


def fly_noise(scenario, backend: str, seeds: list, steps: int, noise: str, device="cpu"):
    sim = FormationSim(scenario, len(seeds), options=SimOptions(backend, device, noise=noise))
    first = sim.reset(seed=seeds)
    states, disturbances = [to_numpy(first.z).copy()], []
    u = np.zeros((len(seeds), scenario.n_uav, 3))
    for _ in range(steps):
        result = sim.step(u)
        states.append(to_numpy(result.z).copy())
        disturbances.append(to_numpy(result.disturbance).copy())
    return np.stack(states), np.stack(disturbances)


@pytest.mark.parametrize("device", DEVICES)
def test_counter_noise_is_the_same_on_numpy_and_torch(device: str) -> None:
    """noise="counter": the noise is drawn on the device, and a gusty, windy episode on torch
    equals the numpy one (counter uniforms are bit-identical, normals to an ulp)."""
    from uav_formation_env.scenarios import make_scenario

    windy = make_scenario(wind=(0.0, 0.3, 0.0), gust_std=0.1)
    z_np, d_np = fly_noise(windy, "numpy", [4, 7], 150, "counter")
    z, d = fly_noise(windy, "torch", [4, 7], 150, "counter", device)
    np.testing.assert_allclose(d, d_np, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(z, z_np, rtol=1e-9, atol=1e-9)


def test_counter_noise_names_the_episode_by_its_seed() -> None:
    """A seed flies the same alone and in a batch; the scene and start are those of the
    generator noise (only the noise differs), with the same statistics."""
    scenario = paper_scenario()
    z_batch, d_batch = fly_noise(scenario, "numpy", [9, 3, 5], 300, "counter")
    z_alone, d_alone = fly_noise(scenario, "numpy", [3], 300, "counter")
    np.testing.assert_array_equal(d_alone[:, 0], d_batch[:, 1])
    np.testing.assert_array_equal(z_alone[:, 0], z_batch[:, 1])
    z_gen, d_gen = fly_noise(scenario, "numpy", [9, 3, 5], 300, "generator")
    np.testing.assert_array_equal(z_gen[0], z_batch[0])  # the same start
    assert np.abs(d_gen - d_batch).max() > 1e-3  # not the same noise
    for stat in (np.mean, np.std):
        assert stat(np.abs(d_batch)) == pytest.approx(stat(np.abs(d_gen)), rel=0.05)
    with pytest.raises(ValueError, match="noise must be one of"):
        SimOptions(noise="philox")


def test_counter_noise_is_fresh_uniform_noise_every_step() -> None:
    sim = FormationSim(paper_scenario(), 2, options=SimOptions(noise="counter"))
    sim.reset(seed=[0, 1])
    draws = []
    for _ in range(400):
        draws.append(sim._step_noise())
        sim.step(np.zeros((2, 5, 3)))
    noise = np.stack(draws)  # (T, B, N, uniform columns)
    assert noise.shape[-1] == sim.disturbance.noise_dim > 0
    assert noise.min() >= 0.0 and noise.max() < 1.0
    assert noise.mean() == pytest.approx(0.5, abs=0.02)
    assert (np.diff(noise, axis=0) != 0).all()  # a new draw every step
    assert (noise[:, 0] != noise[:, 1]).all()  # and every copy
