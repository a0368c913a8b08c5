"""A whole episode on the torch backend equals the numpy episode (issue 14, "Equality").

The numpy simulator is the reference. The torch simulator (float64; CPU in CI, CUDA when present)
gets the same inputs: each copy's numpy Generator draws the same scene, start and noise on both
backends, so every state, cost and output must agree to 1e-9 (relative), at every step.
"""

from __future__ import annotations

from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from uav_formation_env.config_io import paper_scenario
from uav_formation_env.core.array_api import to_numpy
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


def test_compiled_observer_step_equals_the_eager_one(monkeypatch) -> None:
    """SimOptions(compile=True): the observer's ticks through torch.compile give the eager
    numbers (to rounding); where compilation fails, one warning and the eager loop."""
    from uav_formation_env.core import observer

    scenario = paper_scenario()
    runs = []
    for compile_ in (False, True):
        sim = FormationSim(scenario, 3, options=SimOptions("torch", compile=compile_))
        sim.reset(seed=[1, 2, 3])
        states = [to_numpy(sim.step(torch.full((3, 5, 3), 0.5, dtype=torch.float64)).z).copy()]
        for _ in range(4):
            states.append(to_numpy(sim.step(torch.zeros((3, 5, 3), dtype=torch.float64)).z))
        runs.append((np.stack(states), to_numpy(sim.observer.d_hat)))
    np.testing.assert_allclose(runs[1][0], runs[0][0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(runs[1][1], runs[0][1], rtol=1e-10, atol=1e-12)

    def broken(*args, **kwargs):
        raise RuntimeError("no compiler here")

    monkeypatch.setattr(observer, "_COMPILED_HELD", [broken])
    sim = FormationSim(scenario, 3, options=SimOptions("torch", compile=True))
    sim.reset(seed=[1, 2, 3])
    with pytest.warns(RuntimeWarning, match="torch.compile of the observer step failed"):
        z = sim.step(torch.full((3, 5, 3), 0.5, dtype=torch.float64)).z
    np.testing.assert_allclose(to_numpy(z), runs[0][0][0], rtol=1e-12, atol=1e-12)
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
