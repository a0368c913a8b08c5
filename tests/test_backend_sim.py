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
    candidate = FormationSim(scenario, batch_size=batch, backend="torch", device=device)
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
        FormationSim(scenario, backend="jax")
    with pytest.raises(ValueError, match="runs on device 'cpu' only"):
        FormationSim(scenario, backend="numpy", device="cuda")
    with pytest.raises(ValueError, match="device must name a torch device"):
        FormationSim(scenario, backend="torch", device="moon")


def test_compiled_observer_step_equals_the_eager_one(monkeypatch) -> None:
    """FormationSim(compile=True): the observer's ticks through torch.compile give the eager
    numbers (to rounding); where compilation fails, one warning and the eager loop."""
    from uav_formation_env.core import observer

    scenario = paper_scenario()
    runs = []
    for compile_ in (False, True):
        sim = FormationSim(scenario, batch_size=3, backend="torch", compile=compile_)
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
    sim = FormationSim(scenario, batch_size=3, backend="torch", compile=True)
    sim.reset(seed=[1, 2, 3])
    with pytest.warns(RuntimeWarning, match="torch.compile of the observer step failed"):
        z = sim.step(torch.full((3, 5, 3), 0.5, dtype=torch.float64)).z
    np.testing.assert_allclose(to_numpy(z), runs[0][0][0], rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="compile=True needs backend='torch'"):
        FormationSim(scenario, compile=True)
