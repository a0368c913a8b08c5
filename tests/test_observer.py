"""Tests of the NFTSMO disturbance observer (docs/model.md §3) in a plant + observer closed loop.

The loop is written here as in a simulator: per control step draw d, u = compensation
(+ command), a = u + d, run the observer over the tick velocities of the step, then advance the
plant by zoh_step.

Measured with the default gains, 5 UAVs, paper disturbance, seed 7, 200 s (docs/model.md §3.2-3.4
say
≈ 0.010 m/s^2 and 0.09 m/s):
  rms(d_hat + s0 - d), t > 10 s            ≈ 0.0097 m/s^2  (seeds 0-5: 0.0096-0.0097)
  rms(d_hat - d) (estimate_without_s0)     ≈ 0.029 m/s^2   (seeds 0-5: 0.027-0.036)
  max |v(t) - v(0)| with -estimate         ≈ 0.11 m/s      (seeds 0-5: 0.11-0.15)
  ... with no compensation                 ≈ 12.0 m/s
  ... with +estimate                       ≈ 23.9 m/s
  ... with -d_hat only (without s0)        ≈ 8.2 m/s
  test disturbance (step + 13 s sinusoid)  rms ≈ 0.006 m/s^2
  one substep (h = dt = 0.2 s): the estimate diverges to inf/nan after 70-90 steps for seeds 0-7;
  rms over the first 50 steps ≈ 0.35-0.66 m/s^2 (≈ 40-70x worse than with 20 substeps).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from uav_formation_env.config import DisturbanceConfig, ObserverConfig
from uav_formation_env.core.disturbances import Disturbance
from uav_formation_env.core.dynamics import zoh_step
from uav_formation_env.core.observer import (
    ObserverState,
    compensation,
    disturbance_estimate,
    observer_init,
    observer_step,
    tick_velocities,
)

DT = 0.2
N_UAV = 5
N_STEPS = 1000  # 200 s
SEED = 7
TIMES = np.arange(N_STEPS) * DT
SETTLED = TIMES > 10.0


def paper_disturbance(seed: int = SEED, n_steps: int = N_STEPS) -> np.ndarray:
    """(n_steps, N, 3) eq. 21 disturbance of one seeded copy, via Disturbance.evaluate."""
    dist = Disturbance(DisturbanceConfig(), N_UAV, DT)
    noise = dist.draw_noise(np.random.default_rng(seed), n_steps)
    gust = np.zeros((1, N_UAV, 3))
    return np.stack(
        [dist.evaluate(np.array([k * DT]), noise[k][None], gust)[0][0] for k in range(n_steps)]
    )


def custom_disturbance() -> np.ndarray:
    """A disturbance used nowhere else: 0.15 m/s^2 step at t = 30 s + 13 s sinusoid of 0.1."""
    t = TIMES[:, None, None]
    phase = np.arange(N_UAV)[None, :, None] * 0.7 + np.array([0.0, 1.0, 2.0])[None, None, :]
    sign = np.array([1.0, -1.0, 1.0])
    step = 0.15 * (t >= 30.0) * sign
    wave = 0.1 * np.sin(2 * np.pi * t / 13.0 + phase)
    return step + wave


def closed_loop(
    d: np.ndarray, config: ObserverConfig, mode: str = "minus", command: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate plant + observer.

    Returns the estimate at the end of each step (S, N, 3) and the velocities v (S+1, N, 3).

    mode: "minus" applies u = compensation() = -estimate, "plus" applies +estimate, "off" none.
    """
    substeps = config.substeps
    h = DT / substeps
    n_steps = d.shape[0]
    z = np.zeros((N_UAV, 6))
    z[:, 3] = 20.0
    state = observer_init(z[:, 3:])
    estimates = np.empty((n_steps, N_UAV, 3))
    velocities = np.empty((n_steps + 1, N_UAV, 3))
    velocities[0] = z[:, 3:]
    for k in range(n_steps):
        if mode == "minus":
            u = compensation(state, config)
        elif mode == "plus":
            u = -compensation(state, config)
        else:
            u = np.zeros((N_UAV, 3))
        if command is not None:
            u = u + command[k]
        a = u + d[k]
        state = observer_step(state, tick_velocities(z[:, 3:], a, DT, substeps), u, h, config)
        z = zoh_step(z, a, DT)
        estimates[k] = disturbance_estimate(state, config)
        velocities[k + 1] = z[:, 3:]
    return estimates, velocities


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


@pytest.fixture(scope="module")
def d_paper() -> np.ndarray:
    return paper_disturbance()


@pytest.fixture(scope="module")
def default_run(d_paper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return closed_loop(d_paper, ObserverConfig(), "minus")


# ------------------------------------------------------------------------------------------------
# estimation accuracy
# ------------------------------------------------------------------------------------------------


def test_paper_disturbance_is_tracked(d_paper: np.ndarray, default_run) -> None:
    estimates, _ = default_run
    err = estimates - d_paper
    assert np.isfinite(err).all()
    assert rms(err[SETTLED]) <= 0.02  # measured ≈ 0.0097
    # every UAV and every axis separately
    per_channel = np.sqrt(np.mean(err[SETTLED] ** 2, axis=0))
    assert per_channel.max() <= 0.02
    # it is a real estimate: far better than estimating zero or the mean
    assert rms(d_paper[SETTLED]) > 0.1
    assert rms(err[SETTLED]) < 0.2 * rms(d_paper[SETTLED] - d_paper[SETTLED].mean(axis=0))


def test_unseen_disturbance_is_tracked() -> None:
    d = custom_disturbance()
    assert d.shape == (N_STEPS, N_UAV, 3)
    estimates, velocities = closed_loop(d, ObserverConfig(), "minus")
    err = estimates - d
    assert rms(err[SETTLED]) <= 0.02  # measured ≈ 0.006
    # the step at t = 30 s is picked up within 2 s
    after = (TIMES >= 32.0) & (TIMES < 40.0)
    assert np.abs(err[after]).max() <= 0.05
    assert np.abs(velocities - velocities[0]).max() <= 0.2


def test_estimate_does_not_depend_on_known_input(d_paper: np.ndarray, default_run) -> None:
    """The observer is fed the applied u, so a known command does not disturb the estimate."""
    rng = np.random.default_rng(3)
    n = 200
    command = rng.uniform(-2.0, 2.0, (n, N_UAV, 3))
    est_cmd, _ = closed_loop(d_paper[:n], ObserverConfig(), "minus", command=command)
    est_ref, _ = default_run
    settled = SETTLED[:n]
    assert rms((est_cmd - d_paper[:n])[settled]) <= 0.02
    # and not identical to the no-command run (the command did reach the plant and observer)
    assert not np.array_equal(est_cmd, est_ref[:n])


def test_estimate_without_s0_is_worse(d_paper: np.ndarray, default_run) -> None:
    estimates, _ = default_run
    literal = ObserverConfig(estimate_without_s0=True)
    est_lit, _ = closed_loop(d_paper, literal, "minus")
    err_default = rms((estimates - d_paper)[SETTLED])
    err_literal = rms((est_lit - d_paper)[SETTLED])
    # docs/model.md §3.2: rms(d_hat - d) ≈ 0.02-0.08 vs ≈ 0.010; measured 0.029 vs 0.0097
    assert 0.015 <= err_literal <= 0.08
    assert err_literal > 2.0 * err_default


def test_one_substep_is_much_worse(d_paper: np.ndarray, default_run) -> None:
    """docs/model.md §3.3: h = dt (1 tick per step) diverges or chatters. Measured: non-finite
    after 70-90
    steps (seeds 0-7); rms over the first 50 steps ≈ 0.37 m/s^2 (seed 7) vs ≈ 0.01."""
    estimates, _ = default_run
    err_default = rms((estimates - d_paper)[SETTLED])
    with np.errstate(all="ignore"):
        est_one, _ = closed_loop(d_paper, ObserverConfig(substeps=1), "off")
        err = est_one - d_paper
        finite = bool(np.isfinite(err).all())
        worst = rms(err[:50])
    assert (not finite) or rms(err[SETTLED]) > 10 * err_default
    assert worst > 10 * err_default


def test_forty_substeps_also_work(d_paper: np.ndarray) -> None:
    estimates, _ = closed_loop(d_paper[:300], ObserverConfig(substeps=40), "minus")
    assert rms((estimates - d_paper[:300])[SETTLED[:300]]) <= 0.02


# ------------------------------------------------------------------------------------------------
# compensation
# ------------------------------------------------------------------------------------------------


def test_compensation_removes_drift(d_paper: np.ndarray, default_run) -> None:
    _, v_comp = default_run
    _, v_open = closed_loop(d_paper, ObserverConfig(), "off")
    _, v_plus = closed_loop(d_paper, ObserverConfig(), "plus")
    drift_comp = np.abs(v_comp - v_comp[0]).max()
    drift_open = np.abs(v_open - v_open[0]).max()
    drift_plus = np.abs(v_plus - v_plus[0]).max()
    assert drift_comp <= 0.2  # measured ≈ 0.11
    assert drift_open > 2.0  # measured ≈ 12.0: the +0.05 m/s^2 bias over 200 s
    assert drift_plus > 1.5 * drift_open  # measured ≈ 23.9: +estimate doubles d
    # open-loop drift is what the disturbance integrates to: v(T) - v(0) = Σ d dt
    np.testing.assert_allclose(v_open[-1] - v_open[0], d_paper.sum(axis=0) * DT, atol=1e-9)


def test_compensation_is_minus_estimate() -> None:
    state = ObserverState(
        v_hat=np.zeros(3),
        s0=np.array([0.1, -0.2, 0.05]),
        d_hat=np.array([0.3, 0.1, -0.4]),
        e_prev=np.zeros(3),
    )
    cfg = ObserverConfig()
    np.testing.assert_allclose(disturbance_estimate(state, cfg), [0.4, -0.1, -0.35], atol=1e-15)
    np.testing.assert_allclose(compensation(state, cfg), [-0.4, 0.1, 0.35], atol=1e-15)
    lit = ObserverConfig(estimate_without_s0=True)
    np.testing.assert_allclose(compensation(state, lit), [-0.3, -0.1, 0.4], atol=1e-15)
    # the estimate is a copy, not a view of the state
    est = disturbance_estimate(state, lit)
    est[0] = 99.0
    assert state.d_hat[0] == 0.3


# ------------------------------------------------------------------------------------------------
# one step by hand, purity, tick velocities
# ------------------------------------------------------------------------------------------------


def test_observer_single_tick_by_hand() -> None:
    cfg = ObserverConfig()  # Π1 = 1, λ1 = 2, Π2 = 2, λ2 = 1.5, η = 0.5, ρ = 2
    h = 0.01
    state = ObserverState(
        v_hat=np.array([20.0]),
        s0=np.array([0.05]),
        d_hat=np.array([-0.1]),
        e_prev=np.array([0.02]),
    )
    u = np.array([1.0])
    v = np.array([[20.1]])  # one tick
    new = observer_step(state, v, u, h, cfg)
    e = 20.1 - 20.0  # 0.1
    e_dot = (e - 0.02) / h  # 8.0
    s = e + 1.0 * e**2 + 2.0 * e_dot**1.5  # sig^λ(x) = |x|^λ sign(x)
    v_hat = 20.0 + h * (1.0 + 0.05 - 0.1)
    s0 = 0.05 + h * (1.0 + 1.0 * 2.0 * abs(e) ** 1.0) * e_dot**0.5 / (2.0 * 1.5)
    d_hat = -0.1 + h * (0.5 * 1.0 + 2.0 * s)
    np.testing.assert_allclose(new.v_hat, [v_hat], rtol=1e-14)
    np.testing.assert_allclose(new.s0, [s0], rtol=1e-14)
    np.testing.assert_allclose(new.d_hat, [d_hat], rtol=1e-14)
    np.testing.assert_allclose(new.e_prev, [e], rtol=1e-14)
    # literal sign law: d_hat += h (η + ρ) sign(s)
    lit = observer_step(state, v, u, h, dataclasses.replace(cfg, literal_sign_law=True))
    np.testing.assert_allclose(lit.d_hat, [-0.1 + h * 2.5], rtol=1e-14)
    # negative errors use sign: the update is odd in (e, e_prev, v_hat - v)
    mirror = ObserverState(-state.v_hat, -state.s0, -state.d_hat, -state.e_prev)
    neg = observer_step(mirror, -v, -u, h, cfg)
    np.testing.assert_allclose(neg.d_hat, -new.d_hat, rtol=1e-14)
    np.testing.assert_allclose(neg.s0, -new.s0, rtol=1e-14)


def reference_observer_step(
    state: ObserverState, v_ticks: np.ndarray, u: np.ndarray, h: float, c: ObserverConfig
) -> ObserverState:
    """docs/model.md §3.3 written literally (generic powers, no shortcuts), for comparison."""

    def sig(x: np.ndarray, p: float) -> np.ndarray:
        return np.abs(x) ** p * np.sign(x)

    v_hat, s0, d_hat, e_prev = (
        a.copy() for a in (state.v_hat, state.s0, state.d_hat, state.e_prev)
    )
    for v in v_ticks:
        e = v - v_hat
        e_dot = (e - e_prev) / h
        e_prev = e
        s = e + c.pi1 * sig(e, c.lambda1) + c.pi2 * sig(e_dot, c.lambda2)
        v_hat = v_hat + h * (u + s0 + d_hat)
        s0 = s0 + h * (1 + c.pi1 * c.lambda1 * np.abs(e) ** (c.lambda1 - 1)) * sig(
            e_dot, 2 - c.lambda2
        ) / (c.pi2 * c.lambda2)
        if c.literal_sign_law:
            d_hat = d_hat + h * (c.eta + c.rho) * np.sign(s)
        else:
            d_hat = d_hat + h * (c.eta * np.sign(s) + c.rho * s)
    return ObserverState(v_hat, s0, d_hat, e_prev)


@pytest.mark.parametrize(
    "config",
    [
        ObserverConfig(),
        ObserverConfig(lambda1=2.5, lambda2=1.25, pi1=0.7, pi2=3.0, eta=0.3, rho=1.1),
        ObserverConfig(lambda1=2.0, lambda2=1.7),
        ObserverConfig(literal_sign_law=True),
        ObserverConfig(rho=0.0),
    ],
    ids=["default", "generic", "lambda2=1.7", "literal", "rho=0"],
)
def test_observer_step_matches_literal_spec(config: ObserverConfig) -> None:
    """observer_step equals docs/model.md §3.3 written literally, over one 20-tick step of random
    data
    (the module has a shortcut for λ1 = 2, λ2 = 1.5; this covers it and the generic path)."""
    rng = np.random.default_rng(5)
    shape = (4, N_UAV, 3)
    state = ObserverState(
        v_hat=20.0 + rng.normal(0, 0.1, shape),
        s0=rng.normal(0, 0.1, shape),
        d_hat=rng.normal(0, 0.1, shape),
        e_prev=rng.normal(0, 0.01, shape),
    )
    v0 = 20.0 + rng.normal(0, 0.1, shape)
    u = rng.uniform(-2, 2, shape)
    ticks = np.stack(list(tick_velocities(v0, u + rng.uniform(-0.3, 0.3, shape), DT, 20)))
    got = observer_step(state, ticks, u, DT / 20, config)
    want = reference_observer_step(state, ticks, u, DT / 20, config)
    for name in ("v_hat", "s0", "d_hat", "e_prev"):
        np.testing.assert_allclose(
            getattr(got, name), getattr(want, name), rtol=1e-11, atol=1e-12, err_msg=name
        )


def test_observer_step_does_not_mutate_input() -> None:
    rng = np.random.default_rng(0)
    state = ObserverState(*(rng.normal(size=(N_UAV, 3)) for _ in range(4)))
    before = state.copy()
    v_ticks = np.stack(
        list(tick_velocities(rng.normal(size=(N_UAV, 3)), rng.normal(size=(N_UAV, 3)), DT, 20))
    )
    u = rng.normal(size=(N_UAV, 3))
    u_before = u.copy()
    new = observer_step(state, v_ticks, u, DT / 20, ObserverConfig())
    for name in ("v_hat", "s0", "d_hat", "e_prev"):
        np.testing.assert_array_equal(getattr(state, name), getattr(before, name))
        assert not np.shares_memory(getattr(new, name), getattr(state, name))
        assert not np.array_equal(getattr(new, name), getattr(state, name))
    np.testing.assert_array_equal(u, u_before)


def test_observer_init() -> None:
    v = np.array([[20.0, 0.0, 0.0], [19.0, 1.0, -0.5]])
    state = observer_init(v)
    np.testing.assert_array_equal(state.v_hat, v)
    assert not np.shares_memory(state.v_hat, v)
    for arr in (state.s0, state.d_hat, state.e_prev):
        np.testing.assert_array_equal(arr, np.zeros_like(v))
    assert not np.shares_memory(state.s0, state.d_hat)


def test_no_disturbance_keeps_estimate_near_zero() -> None:
    """d = 0. With u = 0 the error is exactly 0 and nothing moves. With a known u the error is only
    round-off, but sign(s) acts on it, so d_hat chatters by about η h per tick (measured max
    |estimate| ≈ 0.011 m/s^2 over 500 steps of random |u| <= 2): bounded, no drift."""
    cfg = ObserverConfig()
    v0 = np.full((N_UAV, 3), 20.0)
    still = observer_step(
        observer_init(v0),
        tick_velocities(v0, np.zeros_like(v0), DT, 20),
        np.zeros_like(v0),
        DT / 20,
        cfg,
    )
    np.testing.assert_array_equal(disturbance_estimate(still, cfg), 0.0)
    np.testing.assert_array_equal(still.v_hat, v0)
    rng = np.random.default_rng(1)
    state = observer_init(v0)
    v = v0.copy()
    worst = 0.0
    for _ in range(500):
        u = rng.uniform(-2.0, 2.0, (N_UAV, 3))
        state = observer_step(state, tick_velocities(v, u, DT, 20), u, DT / 20, cfg)
        v = v + u * DT
        worst = max(worst, float(np.abs(disturbance_estimate(state, cfg)).max()))
    assert worst <= 0.02
    assert np.abs(state.v_hat - v).max() < 1e-3


def test_tick_velocities() -> None:
    v0 = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    a = np.array([[1.0, -1.0, 0.0], [2.0, 0.0, 4.0]])
    ticks = np.stack(list(tick_velocities(v0, a, 0.2, 4)))
    assert ticks.shape == (4, 2, 3)
    for j in range(4):
        np.testing.assert_allclose(ticks[j], v0 + j * 0.05 * a, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(ticks[0], v0)
    assert math.isclose(float(ticks[-1, 1, 2]), 0.6, rel_tol=1e-15)


@pytest.mark.parametrize("batch", [1, 7])
def test_compiled_kernel_equals_numpy_reference(batch: int) -> None:
    """The optional numba kernel repeats the numpy loop's arithmetic: bit-identical results for
    the default exponents (and the literal sign law), over a closed loop of 200 steps."""
    from uav_formation_env.core import observer_kernel
    from uav_formation_env.core.observer import observer_step_held

    if not observer_kernel.AVAILABLE:
        pytest.skip("numba not installed (the [fast] extra)")
    rng = np.random.default_rng(batch)
    shape = (batch, N_UAV, 3)
    for config in (ObserverConfig(), ObserverConfig(literal_sign_law=True)):
        v = 20.0 + rng.normal(0.0, 0.1, shape)
        ref = fast = observer_init(v)
        for _ in range(200):
            accel = rng.normal(0.0, 0.3, shape)
            u = accel - rng.normal(0.0, 0.1, shape)
            ref = observer_step_held(ref, v, accel, u, DT, config, compiled=False)
            fast = observer_step_held(fast, v, accel, u, DT, config, compiled=True)
            v = v + DT * accel
        for name in ("v_hat", "s0", "d_hat", "e_prev"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(ref, name), err_msg=name)
        assert np.abs(ref.d_hat).max() > 0.01  # the loop did something
