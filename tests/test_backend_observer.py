"""The NFTSMO observer and the disturbance evaluation on both backends.

numpy is the reference (the numba kernel where installed, else the numpy loop); torch float64 (on
the CPU, and on CUDA when present) must give the same numbers. The noise stays drawn by numpy
Generators and is moved to the device, as the torch simulator does.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env.config import DisturbanceConfig
from uav_formation_env.core import observer_kernel
from uav_formation_env.core.array_api import to_numpy
from uav_formation_env.core.disturbances import CopyDisturbance, Disturbance, paper_sinusoid
from uav_formation_env.core.observer import (
    ObserverState,
    compensation,
    disturbance_estimate,
    observer_init,
    observer_step,
    observer_step_held,
    tick_velocities,
)
from uav_formation_env.scenarios import make_scenario

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
TOL = dict(rtol=1e-12, atol=1e-12)
PAPER = make_scenario()
DT = PAPER.dynamics.dt
FIELDS = ("v_hat", "s0", "d_hat", "e_prev")

OBSERVER_CONFIGS = {
    "paper": PAPER.observer,  # λ1 = 2, λ2 = 1.5: the square-root law
    "literal": dataclasses.replace(PAPER.observer, literal_sign_law=True, estimate_without_s0=True),
    "powers": dataclasses.replace(PAPER.observer, lambda1=2.5, lambda2=1.25, substeps=7),
}


def _on(x, device):
    return torch.as_tensor(x, device=device)


def _assert_state_equal(got: ObserverState, expected: ObserverState) -> None:
    for name in FIELDS:
        np.testing.assert_allclose(
            to_numpy(getattr(got, name)), getattr(expected, name), err_msg=name, **TOL
        )


# ------------------------------------------------------------------------------------------------
# observer
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("config_name", list(OBSERVER_CONFIGS))
@pytest.mark.parametrize("shape", [(1, 5, 3), (6, 5, 3), (3,)])
def test_observer_many_steps_equal_on_torch(device, config_name, shape) -> None:
    """200 control steps (20 inner ticks each for the paper's gains) with random held
    accelerations: the sliding-mode switch chatters about s = 0, so this only passes when the
    torch loop repeats numpy's arithmetic exactly."""
    config = OBSERVER_CONFIGS[config_name]
    steps = 200 if config_name == "paper" else 60
    rng = np.random.default_rng([list(OBSERVER_CONFIGS).index(config_name), len(shape), shape[0]])
    v = rng.normal(size=shape) * 5.0
    reference = observer_init(v)  # numpy: the kernel where numba is installed
    loop = observer_init(v)  # numpy: the numpy loop
    state = observer_init(_on(v, device))
    for k in range(steps):
        accel = rng.normal(size=shape) * 0.5
        u = rng.uniform(-1.0, 1.0, size=shape)
        reference = observer_step_held(reference, v, accel, u, DT, config)
        loop = observer_step_held(loop, v, accel, u, DT, config, compiled=False)
        state = observer_step_held(
            state, _on(v, device), _on(accel, device), _on(u, device), DT, config
        )
        if k % 50 == 0 or k == steps - 1:
            _assert_state_equal(state, reference)
            _assert_state_equal(state, loop)
        v = v + accel * DT
    assert state.v_hat.device.type == torch.device(device).type
    assert state.v_hat.dtype == torch.float64
    np.testing.assert_allclose(
        to_numpy(compensation(state, config)), compensation(reference, config), **TOL
    )
    np.testing.assert_allclose(
        to_numpy(disturbance_estimate(state, config)),
        disturbance_estimate(reference, config),
        **TOL,
    )
    # the estimate tracks something: the test is not comparing zeros
    assert np.abs(disturbance_estimate(reference, config)).max() > 1e-3


@pytest.mark.parametrize("device", DEVICES)
def test_observer_step_takes_a_tick_array_and_keeps_its_input(device) -> None:
    rng = np.random.default_rng(3)
    config = PAPER.observer
    shape = (4, 5, 3)
    state_np = ObserverState(*(rng.normal(size=shape) for _ in FIELDS))
    ticks = rng.normal(size=(config.substeps, *shape))
    u = rng.normal(size=shape)
    # e' = 0 exactly in some entries: sig^0.5(0) must be +0 on both
    ticks[0, 0] = state_np.v_hat[0] + state_np.e_prev[0]
    state = ObserverState(*(_on(getattr(state_np, f), device) for f in FIELDS))
    before = state.copy()
    got = observer_step(state, _on(ticks, device), _on(u, device), DT / config.substeps, config)
    expected = observer_step(state_np, ticks, u, DT / config.substeps, config)
    _assert_state_equal(got, expected)
    for name in FIELDS:  # the input state is not modified
        assert torch.equal(getattr(state, name), getattr(before, name))


@pytest.mark.parametrize("device", DEVICES)
def test_tick_velocities_equal_on_torch(device) -> None:
    rng = np.random.default_rng(4)
    v0, a = rng.normal(size=(2, 5, 3)), rng.normal(size=(2, 5, 3))
    got = list(tick_velocities(_on(v0, device), _on(a, device), DT, 20))
    expected = list(tick_velocities(v0, a, DT, 20))
    assert len(got) == len(expected) == 20
    for g, e in zip(got, expected):
        np.testing.assert_allclose(to_numpy(g), e, **TOL)


@pytest.mark.parametrize("device", DEVICES)
def test_observer_init_and_copy_on_torch(device) -> None:
    v = _on(np.arange(6.0).reshape(2, 3), device)
    state = observer_init(v)
    assert state.v_hat.dtype == torch.float64 and state.s0.device == v.device
    state.v_hat[0, 0] = 99.0  # v_hat is a copy of v
    assert float(v[0, 0]) == 0.0
    twin = state.copy()
    for name in FIELDS:
        getattr(twin, name)[...] = -1.0  # the copy shares no memory
        assert float(getattr(state, name)[1, 1]) != -1.0
    assert observer_init(v.to(torch.float32)).s0.dtype == torch.float32  # floats keep their type
    assert observer_init(_on(np.arange(3), device)).v_hat.dtype == torch.float64  # ints: float64
    estimate_only = dataclasses.replace(PAPER.observer, estimate_without_s0=True)
    estimate = disturbance_estimate(state, estimate_only)
    estimate[...] = 5.0  # a new array, not d_hat itself
    assert float(state.d_hat.abs().max()) == 0.0


def test_observer_kernel_is_numpy_only() -> None:
    state = observer_init(torch.zeros(5, 3, dtype=torch.float64))
    zeros = torch.zeros(5, 3, dtype=torch.float64)
    with pytest.raises(TypeError, match="numba kernel is numpy-only"):
        observer_step_held(state, zeros, zeros, zeros, DT, PAPER.observer, compiled=True)
    # compiled=None picks the array-API loop for torch, whether numba is installed or not
    new = observer_step_held(state, zeros, zeros, zeros, DT, PAPER.observer)
    assert isinstance(new.v_hat, torch.Tensor)


@pytest.mark.skipif(not observer_kernel.AVAILABLE, reason="numba not installed")
def test_numpy_inputs_still_take_the_kernel(monkeypatch) -> None:
    calls = []
    kernel = observer_kernel.compiled_step
    monkeypatch.setattr(observer_kernel, "compiled_step", lambda *a: calls.append(1) or kernel(*a))
    zeros = np.zeros((2, 5, 3))
    observer_step_held(observer_init(zeros), zeros, zeros, zeros, DT, PAPER.observer)
    assert calls == [1]
    observer_step_held(
        observer_init(torch.as_tensor(zeros)), *(torch.as_tensor(zeros),) * 3, DT, PAPER.observer
    )
    assert calls == [1]


# ------------------------------------------------------------------------------------------------
# disturbances
# ------------------------------------------------------------------------------------------------

DISTURBANCE_CONFIGS = {
    "paper": PAPER.disturbance,
    "windy": dataclasses.replace(PAPER.disturbance, wind=(0.1, 0.3, -0.2), gust_std=0.1),
    "scalar_rand": dataclasses.replace(PAPER.disturbance, scalar_rand=True, gust_std=0.2),
    "gust_only": DisturbanceConfig(model="none", gust_std=0.3, wind=(0.0, 0.2, 0.0)),
    "none": DisturbanceConfig(model="none"),
}


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("config_name", list(DISTURBANCE_CONFIGS))
@pytest.mark.parametrize("batch", [1, 5])
@pytest.mark.parametrize("copies", [False, True])
def test_disturbance_evaluate_equal_on_torch(device, config_name, batch, copies) -> None:
    """Several steps with the gust state fed back; noise drawn per copy by numpy Generators."""
    config, n_uav = DISTURBANCE_CONFIGS[config_name], 5
    model = Disturbance(config, n_uav, DT)
    rngs = [np.random.default_rng(10 + b) for b in range(batch)]
    noise = np.stack([model.draw_noise(rng, 30) for rng in rngs], axis=1)  # (30, B, N, dim)
    gust = np.stack([model.initial_gust(rng) for rng in rngs])
    per_copy = None
    if copies:  # per-copy parameters, different in every copy
        per_copy = CopyDisturbance.of(config, batch)
        for b in range(batch):
            wind = tuple(np.random.default_rng(b).uniform(-0.3, 0.3, 3))
            drawn = dataclasses.replace(config, amplitude=0.1 * (b + 1), wind=wind)
            per_copy.set_copy(b, dataclasses.replace(drawn, gust_std=0.05 * b))
    per_copy_t = None
    if per_copy is not None:
        per_copy_t = CopyDisturbance.of(config, batch, like=_on(gust, device))
        for name in ("amplitude", "wind", "gust_std"):
            getattr(per_copy_t, name)[...] = _on(getattr(per_copy, name), device)
    gust_t = _on(gust, device)
    for k in range(30):
        t = np.full(batch, k * DT) + np.arange(batch)  # copies at different times
        d, gust = model.evaluate(t, noise[k], gust, per_copy)
        t_on = t if k % 2 else _on(t, device)  # the step may pass t as numpy too
        d_t, gust_t = model.evaluate(t_on, _on(noise[k], device), gust_t, per_copy_t)
        assert isinstance(d_t, torch.Tensor) and d_t.device.type == torch.device(device).type
        np.testing.assert_allclose(to_numpy(d_t), d, **TOL)
        np.testing.assert_allclose(to_numpy(gust_t), gust, **TOL)
    assert d.shape == (batch, n_uav, 3)
    if config_name != "none":
        assert np.abs(d).max() > 1e-3


@pytest.mark.parametrize("device", DEVICES)
def test_paper_sinusoid_equal_on_torch(device) -> None:
    t = np.array([0.0, 1.0, 10.0, 37.5, 199.8])
    for n_uav, amplitude in ((5, 0.2), (3, 1.5)):
        expected = paper_sinusoid(t, n_uav, amplitude, 40.0)
        got = paper_sinusoid(_on(t, device), n_uav, amplitude, 40.0)
        np.testing.assert_allclose(to_numpy(got), expected, **TOL)
        got[...] = 0.0  # a new array each call: the cached constant is not touched
        assert bool((paper_sinusoid(_on(t, device), n_uav, amplitude, 40.0) != 0).any())
    scalar = paper_sinusoid(_on(np.float64(10.0), device), 5, 0.2, 40.0)
    assert tuple(scalar.shape) == (5, 3)
    np.testing.assert_allclose(to_numpy(scalar), paper_sinusoid(10.0, 5, 0.2, 40.0), **TOL)
    as_float32 = paper_sinusoid(_on(t, device).to(torch.float32), 5, 0.2, 40.0)
    assert as_float32.dtype == torch.float32  # floats keep their type
    ints = paper_sinusoid(_on(np.arange(3), device), 5, 0.2, 40.0)
    assert ints.dtype == torch.float64
    np.testing.assert_allclose(to_numpy(ints), paper_sinusoid(np.arange(3), 5, 0.2, 40.0), **TOL)


@pytest.mark.parametrize("device", DEVICES)
def test_copy_disturbance_of_like_torch(device) -> None:
    config = DisturbanceConfig(amplitude=0.3, wind=(0.1, 0.2, 0.3), gust_std=0.4)
    expected = CopyDisturbance.of(config, 3)
    got = CopyDisturbance.of(config, 3, like=torch.zeros(1, dtype=torch.float64, device=device))
    for name in ("amplitude", "wind", "gust_std"):
        value = getattr(got, name)
        assert value.device.type == torch.device(device).type and value.dtype == torch.float64
        np.testing.assert_array_equal(to_numpy(value), getattr(expected, name))
    other = DisturbanceConfig(amplitude=0.7, wind=(-1.0, 0.0, 2.0), gust_std=0.0)
    got.set_copy(1, other)  # rows are separate memory: only copy 1 changes
    expected.set_copy(1, other)
    for name in ("amplitude", "wind", "gust_std"):
        np.testing.assert_array_equal(to_numpy(getattr(got, name)), getattr(expected, name))
    assert to_numpy(got.wind)[0, 0, 0] == 0.1 and to_numpy(got.wind)[1, 0, 0] == -1.0
    single = CopyDisturbance.of(config, 2, like=torch.zeros(1, dtype=torch.float32))
    assert single.wind.dtype == torch.float32
