"""Tests of the disturbance model (docs/model.md §2, eq. 21), wind and Gauss-Markov gust."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uav_formation_env.config import DisturbanceConfig
from uav_formation_env.core.disturbances import Disturbance, paper_sinusoid

DT = 0.2


def evaluate_one(dist: Disturbance, t: float, noise: np.ndarray) -> np.ndarray:
    """d for one scenario copy at time t with noise (N, noise_dim), gust = 0; returns (N, 3)."""
    gust = np.zeros((1, dist.n_uav, 3))
    d, _ = dist.evaluate(np.array([t]), noise[None], gust)
    assert d.shape == (1, dist.n_uav, 3)
    return d[0]


def series(dist: Disturbance, noise: np.ndarray) -> np.ndarray:
    """d over noise.shape[0] control steps of one copy (no gust state carried), (S, N, 3)."""
    gust = np.zeros((1, dist.n_uav, 3))
    out = np.empty((noise.shape[0], dist.n_uav, 3))
    for k in range(noise.shape[0]):
        out[k] = dist.evaluate(np.array([k * dist.dt]), noise[k][None], gust)[0][0]
    return out


# ------------------------------------------------------------------------------------------------
# eq. 21 by hand
# ------------------------------------------------------------------------------------------------

S = math.sqrt(0.5)
# [sin(πt/20), cos(πt/20), sin(πt/20)] written out for the chosen times
WAVES = {
    0.0: (0.0, 1.0, 0.0),
    10.0: (1.0, 0.0, 1.0),
    20.0: (0.0, -1.0, 0.0),
    35.0: (-S, S, -S),  # 7π/4
}


@pytest.mark.parametrize("t", sorted(WAVES))
def test_eq21_zero_noise_hand_values(t: float) -> None:
    dist = Disturbance(DisturbanceConfig(), n_uav=5, dt=DT)
    assert dist.noise_dim == 3
    d = evaluate_one(dist, t, np.zeros((5, 3)))
    w = np.array(WAVES[t])
    # UAV1 (index 0), UAV3, UAV5 negative; UAV2, UAV4 positive
    expected = np.array([-0.2 * w, 0.2 * w, -0.2 * w, 0.2 * w, -0.2 * w])
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-15)


def test_eq21_uav1_negative_at_t10() -> None:
    dist = Disturbance(DisturbanceConfig(), n_uav=2, dt=DT)
    d = evaluate_one(dist, 10.0, np.zeros((2, 3)))
    np.testing.assert_allclose(d[0], [-0.2, 0.0, -0.2], atol=1e-15)
    np.testing.assert_allclose(d[1], [0.2, 0.0, 0.2], atol=1e-15)


@pytest.mark.parametrize("t", sorted(WAVES))
def test_eq21_chosen_noise_hand_values(t: float) -> None:
    dist = Disturbance(DisturbanceConfig(), n_uav=3, dt=DT)
    r = np.array([[0.3, 0.6, 0.9], [0.0, 0.5, 0.99], [0.25, 0.75, 0.125]])
    d = evaluate_one(dist, t, r)
    w = np.array(WAVES[t])
    expected = np.array(
        [
            -0.2 * w + 0.1 * np.array([0.3, 0.6, 0.9]),
            +0.2 * w + 0.1 * np.array([0.0, 0.5, 0.99]),
            -0.2 * w + 0.1 * np.array([0.25, 0.75, 0.125]),
        ]
    )
    np.testing.assert_allclose(d, expected, rtol=0, atol=1e-15)


def test_eq21_t10_literal_numbers() -> None:
    dist = Disturbance(DisturbanceConfig(), n_uav=2, dt=DT)
    d = evaluate_one(dist, 10.0, np.array([[0.5, 0.5, 0.5], [1.0, 0.0, 0.2]]))
    np.testing.assert_allclose(d, [[-0.15, 0.05, -0.15], [0.3, 0.0, 0.22]], atol=1e-15)


def test_paper_sinusoid_batched_times() -> None:
    t = np.array([0.0, 10.0, 20.0, 35.0])
    wave = paper_sinusoid(t, 4, 0.2, 40.0)
    assert wave.shape == (4, 4, 3)
    for b, tb in enumerate(t):
        w = np.array(WAVES[float(tb)])
        np.testing.assert_allclose(wave[b], [-0.2 * w, 0.2 * w, -0.2 * w, 0.2 * w], atol=1e-15)


def test_period_and_amplitude_are_used() -> None:
    dist = Disturbance(DisturbanceConfig(amplitude=0.5, period=8.0), n_uav=1, dt=DT)
    d = evaluate_one(dist, 2.0, np.zeros((1, 3)))  # 2π·2/8 = π/2
    np.testing.assert_allclose(d[0], [-0.5, 0.0, -0.5], atol=1e-15)


# ------------------------------------------------------------------------------------------------
# noise
# ------------------------------------------------------------------------------------------------


def test_seeded_draws_reproduce_and_differ() -> None:
    dist = Disturbance(DisturbanceConfig(gust_std=0.1), n_uav=5, dt=DT)
    a = dist.draw_noise(np.random.default_rng(123), 50)
    b = dist.draw_noise(np.random.default_rng(123), 50)
    c = dist.draw_noise(np.random.default_rng(124), 50)
    np.testing.assert_array_equal(a, b)
    assert a.tobytes() == b.tobytes()
    assert not np.any(a == c)  # continuous draws: no coincidences
    g1 = dist.initial_gust(np.random.default_rng(9))
    g2 = dist.initial_gust(np.random.default_rng(9))
    np.testing.assert_array_equal(g1, g2)


def test_draw_noise_shape_range_and_independence() -> None:
    n_steps, n_uav = 20000, 5
    dist = Disturbance(DisturbanceConfig(), n_uav=n_uav, dt=DT)
    noise = dist.draw_noise(np.random.default_rng(2024), n_steps)
    assert noise.shape == (n_steps, n_uav, 3)
    assert noise.min() >= 0.0 and noise.max() < 1.0
    cols = noise.reshape(n_steps, n_uav * 3)  # one column per (UAV, axis)
    # no two columns equal (a shared draw would make them equal)
    for i in range(cols.shape[1]):
        for j in range(i + 1, cols.shape[1]):
            assert not np.array_equal(cols[:, i], cols[:, j])
    # correlations across axes and UAVs: each off-diagonal ~ N(0, 1/n); 5 sigma bound
    corr = np.corrcoef(cols, rowvar=False)
    off = corr[~np.eye(corr.shape[0], dtype=bool)]
    assert np.abs(off).max() < 5.0 / math.sqrt(n_steps)
    # independent from one step to the next (lag-1 autocorrelation per column)
    centred = cols - cols.mean(axis=0)
    lag1 = (centred[1:] * centred[:-1]).mean(axis=0) / centred.var(axis=0)
    assert np.abs(lag1).max() < 5.0 / math.sqrt(n_steps)
    # uniform on [0, 1): mean 1/2, variance 1/12 per column
    assert np.abs(cols.mean(axis=0) - 0.5).max() < 5.0 * math.sqrt(1 / 12 / n_steps)
    np.testing.assert_allclose(cols.var(axis=0), 1 / 12, rtol=0.05)


def test_scalar_rand_shares_one_column_over_axes() -> None:
    dist = Disturbance(DisturbanceConfig(scalar_rand=True), n_uav=3, dt=DT)
    assert dist.noise_dim == 1
    noise = dist.draw_noise(np.random.default_rng(0), 200)
    assert noise.shape == (200, 3, 1)
    d = series(dist, noise)
    t = np.arange(200) * DT
    random_part = d - paper_sinusoid(t, 3, 0.2, 40.0)
    np.testing.assert_allclose(random_part, 0.1 * np.repeat(noise, 3, axis=-1), atol=1e-15)
    np.testing.assert_allclose(random_part[..., 0], random_part[..., 1], atol=1e-15)
    np.testing.assert_allclose(random_part[..., 0], random_part[..., 2], atol=1e-15)
    # the default (per-axis) model does not share
    per_axis = Disturbance(DisturbanceConfig(), n_uav=3, dt=DT)
    rp = series(per_axis, per_axis.draw_noise(np.random.default_rng(0), 200)) - paper_sinusoid(
        t, 3, 0.2, 40.0
    )
    assert np.abs(rp[..., 0] - rp[..., 1]).max() > 0.05


def test_random_part_mean_and_bound() -> None:
    n_steps, n_uav = 4000, 5
    dist = Disturbance(DisturbanceConfig(), n_uav=n_uav, dt=DT)
    noise = dist.draw_noise(np.random.default_rng(77), n_steps)
    d = series(dist, noise)
    t = np.arange(n_steps) * DT
    random_part = d - paper_sinusoid(t, n_uav, 0.2, 40.0)
    # mean +0.05 per axis; std of the mean = 0.1 sqrt(1/12) / sqrt(samples)
    samples = n_steps * n_uav
    tol = 5.0 * 0.1 * math.sqrt(1 / 12) / math.sqrt(samples)
    np.testing.assert_allclose(random_part.mean(axis=(0, 1)), 0.05, atol=tol)
    # |d| <= 0.3 per axis, and the bound the module reports
    assert np.abs(d).max() <= 0.3
    assert d.min() >= -0.2 - 1e-12
    assert dist.bound() == pytest.approx(0.3, abs=1e-15)
    # the random part is held over a step: it only depends on that step's noise
    np.testing.assert_allclose(random_part, 0.1 * noise, atol=1e-15)


def test_constant_wind_adds_exactly() -> None:
    wind = (0.25, -0.125, 0.5)
    n_uav = 4
    noise = Disturbance(DisturbanceConfig(), n_uav, DT).draw_noise(np.random.default_rng(1), 30)
    base = series(Disturbance(DisturbanceConfig(), n_uav, DT), noise)
    windy = series(Disturbance(DisturbanceConfig(wind=wind), n_uav, DT), noise)
    np.testing.assert_allclose(windy - base, np.broadcast_to(wind, base.shape), rtol=0, atol=1e-15)
    # wind alone is exactly the wind
    calm = Disturbance(DisturbanceConfig(model="none", wind=wind), n_uav, DT)
    assert calm.noise_dim == 0
    d = series(calm, calm.draw_noise(np.random.default_rng(1), 5))
    np.testing.assert_array_equal(d, np.broadcast_to(wind, (5, n_uav, 3)))
    assert calm.bound() == 0.5


def test_model_none_is_zero() -> None:
    dist = Disturbance(DisturbanceConfig(model="none"), n_uav=5, dt=DT)
    assert dist.noise_dim == 0
    noise = dist.draw_noise(np.random.default_rng(0), 40)
    assert noise.shape == (40, 5, 0)
    d = series(dist, noise)
    np.testing.assert_array_equal(d, 0.0)
    assert dist.bound() == 0.0
    np.testing.assert_array_equal(dist.initial_gust(np.random.default_rng(0)), 0.0)


def test_noise_scale_zero_draws_nothing() -> None:
    dist = Disturbance(DisturbanceConfig(noise_scale=0.0), n_uav=2, dt=DT)
    assert dist.noise_dim == 0
    d = evaluate_one(dist, 10.0, np.zeros((2, 0)))
    np.testing.assert_allclose(d, [[-0.2, 0.0, -0.2], [0.2, 0.0, 0.2]], atol=1e-15)


# ------------------------------------------------------------------------------------------------
# Gauss-Markov gust
# ------------------------------------------------------------------------------------------------


def test_gauss_markov_gust_std_and_autocorrelation() -> None:
    sigma, tau = 0.3, 2.0
    n_uav, n_steps = 50, 4000  # 150 independent AR(1) series of 800 s = 400 τ
    dist = Disturbance(
        DisturbanceConfig(model="none", gust_std=sigma, gust_time_constant=tau), n_uav, DT
    )
    phi = math.exp(-DT / tau)
    assert dist.gust_decay == pytest.approx(phi, rel=1e-15)
    assert dist.noise_dim == 3
    rng = np.random.default_rng(8)
    gust = dist.initial_gust(rng)[None]  # (1, N, 3), stationary start
    noise = dist.draw_noise(rng, n_steps)
    d = np.empty((n_steps, n_uav, 3))
    for k in range(n_steps):
        dk, gust = dist.evaluate(np.array([k * DT]), noise[k][None], gust)
        d[k] = dk[0]
    x = d.reshape(n_steps, -1)
    n_series = x.shape[1]
    # effective number of independent samples of an AR(1) series: n (1 - φ) / (1 + φ)
    n_eff = n_steps * n_series * (1 - phi) / (1 + phi)
    var = (x**2).mean()  # known zero mean
    # sample variance of a Gaussian AR(1): relative std sqrt(2 (1 + φ²) / (1 - φ²) / n)
    rel_se_var = math.sqrt(2 * (1 + phi**2) / (1 - phi**2) / (n_steps * n_series))
    assert abs(var / sigma**2 - 1) < 5 * rel_se_var
    assert abs(math.sqrt(var) - sigma) < 0.02 * sigma
    lag1 = (x[1:] * x[:-1]).mean() / var
    # std of the lag-1 estimate ≈ sqrt((1 - φ²) / n)
    se_lag1 = math.sqrt((1 - phi**2) / (n_steps * n_series))
    assert abs(lag1 - phi) < 5 * se_lag1 + 1e-3
    assert n_eff > 1e4
    # the gust is the disturbance itself here, zero mean
    assert abs(x.mean()) < 5 * sigma / math.sqrt(n_eff)


def test_gust_update_rule_by_hand() -> None:
    sigma, tau = 0.4, 1.0
    dist = Disturbance(
        DisturbanceConfig(model="none", gust_std=sigma, gust_time_constant=tau), n_uav=1, dt=0.5
    )
    phi = math.exp(-0.5)
    gust = np.array([[[0.1, -0.2, 0.3]]])
    xi = np.array([[[1.0, 0.0, -2.0]]])
    d, nxt = dist.evaluate(np.array([0.0]), xi, gust)
    np.testing.assert_array_equal(d, gust)  # d uses the current state
    expected = phi * gust + sigma * math.sqrt(1 - phi**2) * xi
    np.testing.assert_allclose(nxt, expected, rtol=1e-15, atol=1e-16)


def test_initial_gust_is_stationary() -> None:
    sigma = 0.2
    dist = Disturbance(DisturbanceConfig(gust_std=sigma), n_uav=20000, dt=DT)
    g = dist.initial_gust(np.random.default_rng(4))
    assert g.shape == (20000, 3)
    n = g.size
    assert abs(g.std() / sigma - 1) < 5 * math.sqrt(0.5 / n)
    # with the paper model on, noise columns are [3 uniform, 3 normal]
    noise = dist.draw_noise(np.random.default_rng(4), 2)
    assert noise.shape == (2, 20000, 6)
    assert noise[..., :3].min() >= 0 and noise[..., :3].max() < 1
    assert noise[..., 3:].min() < 0
