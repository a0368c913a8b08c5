"""The compiled kernels of :mod:`uav_formation_env.fast_step` (numba, the ``[fast]`` extra).

Each kernel repeats the batched numpy path's operations in the same order: numpy's two-lane sums
of products (``einsum`` of contiguous operands), its sequential reductions over short axes, its
``minimum(maximum(.))`` clips; no fast-math, so no reassociation or fused multiply-adds.
:func:`platform_agrees` checks numpy's summation order on the machine before the kernels are
used. Without numba the kernels are None.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uav_formation_env.core import observer_kernel
from uav_formation_env.core.reference import _TIME_TOL

AVAILABLE = observer_kernel.AVAILABLE


def njit(function: Any) -> Any:
    """``numba.njit(cache=True)``, or without the on-disk cache where it cannot be written
    (a read-only install); None without numba."""
    if not AVAILABLE:
        return None
    numba = observer_kernel.numba
    try:
        return numba.njit(cache=True)(function)
    except (RuntimeError, OSError):  # no cache locator: a read-only package directory
        return numba.njit(function)


# ------------------------------------------------------------------------------------------------
# numpy's arithmetic, operation by operation
# ------------------------------------------------------------------------------------------------


def _dot(x: np.ndarray, y: np.ndarray) -> float:
    """``einsum("k,k->", x, y)`` of contiguous vectors as numpy computes it: two lanes (even,
    odd), eight terms a round, then pairs."""
    acc0 = 0.0
    acc1 = 0.0
    n = x.shape[0]
    k = 0
    while n - k >= 8:  # numpy's unrolled loop: four pairs, the last one added first
        acc0 = x[k] * y[k] + (
            x[k + 2] * y[k + 2] + (x[k + 4] * y[k + 4] + (x[k + 6] * y[k + 6] + acc0))
        )
        acc1 = x[k + 1] * y[k + 1] + (
            x[k + 3] * y[k + 3] + (x[k + 5] * y[k + 5] + (x[k + 7] * y[k + 7] + acc1))
        )
        k += 8
    while k + 1 < n:
        acc0 = acc0 + x[k] * y[k]
        acc1 = acc1 + x[k + 1] * y[k + 1]
        k += 2
    if k < n:
        acc0 = acc0 + x[k] * y[k]
        acc1 = acc1 + 0.0
    return acc0 + acc1


def _clip(x: float, low: float, high: float) -> float:
    """``minimum(maximum(x, low), high)`` (NaN stays NaN)."""
    x = low if x < low else x
    return high if x > high else x


_dot = njit(_dot) or _dot
_clip = njit(_clip) or _clip


# ------------------------------------------------------------------------------------------------
# kernels
# ------------------------------------------------------------------------------------------------


def _advance(
    u_in, z, v_hat, s0, d_hat, e_prev, noise, noise_pos, gust, waves, steps, signed, wind, par,
    gains, status, centres, r_detect_sq, u_n, u_d, u, d, gust_next, new_v_hat, new_s0,
    new_d_hat, new_e_prev, z_next, t_next,
):  # fmt: skip
    """The dynamics of one step (sim.py, steps 1-3), into the given outputs, and whether the
    topology needs the batched update (an obstacle active, or a UAV within an armed obstacle's
    detection radius). ``steps`` (B,) is advanced in place.

    par = (u_max, dt, observer on, estimate without s0, noise scale, uniform columns, gust
    columns, gust decay, innovation scale, substeps, literal sign law, square-root law, rearm,
    paper model); waves (K, 3) = [sin, cos, sin] of eq. 21's phase at step k; signed (N,) = ±A.
    """
    batch, n_uav = z.shape[0], z.shape[1]
    u_max, dt = par[0], par[1]
    observer_on, without_s0 = par[2] != 0.0, par[3] != 0.0
    noise_scale, n_uniform, n_gust = par[4], int(par[5]), int(par[6])
    decay, innovation, substeps = par[7], par[8], int(par[9])
    literal, square_root, rearm, paper = par[10] != 0.0, par[11] != 0.0, par[12] != 0.0, par[13]
    accel = np.empty((batch, n_uav, 3))
    for b in range(batch):
        row = noise[b, noise_pos[b]]
        wave = waves[steps[b]]
        for i in range(n_uav):
            for k in range(3):
                un = _clip(u_in[b, i, k], -u_max, u_max)
                u_n[b, i, k] = un
                ud = 0.0
                if observer_on:
                    ud = -(d_hat[b, i, k] if without_s0 else d_hat[b, i, k] + s0[b, i, k])
                u_d[b, i, k] = ud
                uk = _clip(un + ud, -u_max, u_max)
                u[b, i, k] = uk
                dk = wind[k] + gust[b, i, k]
                if paper != 0.0:
                    dk += signed[i] * wave[k]
                    if n_uniform:
                        dk += noise_scale * row[i, k if n_uniform == 3 else 0]
                d[b, i, k] = dk
                if n_gust:
                    gust_next[b, i, k] = decay * gust[b, i, k] + innovation * row[i, n_uniform + k]
                accel[b, i, k] = uk + dk
        steps[b] += 1
        t_next[b] = steps[b] * dt
    flat = batch * n_uav * 3
    new_v_hat[...] = v_hat
    new_s0[...] = s0
    new_d_hat[...] = d_hat
    new_e_prev[...] = e_prev
    if observer_on:
        v0 = np.ascontiguousarray(z[..., 3:]).reshape(flat)
        observer_kernel.compiled_step(
            v0, accel.reshape(flat), u.reshape(flat), dt, substeps,
            new_v_hat.reshape(flat), new_s0.reshape(flat), new_d_hat.reshape(flat),
            new_e_prev.reshape(flat), gains, literal, square_root,
        )  # fmt: skip
    for b in range(batch):
        for i in range(n_uav):
            for k in range(3):
                dv = accel[b, i, k] * dt
                dp = (z[b, i, 3 + k] + 0.5 * dv) * dt
                z_next[b, i, k] = z[b, i, k] + dp
                z_next[b, i, 3 + k] = z[b, i, 3 + k] + dv
    busy = False
    for b in range(batch):
        for o in range(status.shape[1]):
            if status[b, o] == 1:
                busy = True
            elif status[b, o] == 0 or (rearm and status[b, o] == 2):  # armed
                nearest = math.inf
                for i in range(n_uav):
                    rx = z_next[b, i, 0] - centres[o, 0]
                    ry = z_next[b, i, 1] - centres[o, 1]
                    nearest = min(nearest, rx * rx + ry * ry)
                if nearest < r_detect_sq[o]:
                    busy = True
    return busy


def _finish(
    z, u_n, t, idle, avoiding, h0, times, velocities, offsets, centres, radii, d_hat, s0,
    weights, par, scale, low, high, others, adjacency, reference, pair, separation, surface,
    formation, energy, velocity, gap, obstacle, collision, estimate, obs,
):  # fmt: skip
    """Into the given outputs: the topology outputs of an idle step (``idle``: H0 and the preset
    velocity; else ``adjacency`` and ``reference`` hold the batched update's), distances, the
    stage cost's terms, the estimate and the full observation.

    weights = (q, r, n, s, d_s, o, c_o); par = (duration, sign of the offsets, uav distance,
    sensing radius (inf: none), observer on, estimate without s0, obstacle distance).
    """
    batch, n_uav = z.shape[0], z.shape[1]
    n_obs = radii.shape[0]
    q, r, n_w, s_w, d_s, o_w, c_o = (
        weights[0], weights[1], weights[2], weights[3], weights[4], weights[5], weights[6]
    )  # fmt: skip
    duration, sign, uav_distance, radius = par[0], par[1], par[2], par[3]
    observer_on, without_s0, obstacle_distance = par[4] != 0.0, par[5] != 0.0, par[6]
    a = np.empty((n_uav, 6))
    centred = np.empty((n_uav, 6))
    mean = np.empty(6)
    b_sq = np.empty(n_uav)
    h_b = np.empty(6)
    diff = np.empty(3)
    dim = scale.shape[0]
    raw = np.empty(dim)
    for b in range(batch):
        if idle:
            cut = t[b] - _TIME_TOL
            leg = 0
            for k in range(times.shape[0]):
                if times[k] < cut:
                    leg += 1
            for i in range(n_uav):
                for j in range(n_uav):
                    adjacency[b, i, j] = h0[i, j]
                for k in range(3):
                    reference[b, i, k] = velocities[leg, k]
        # pair distances (+inf on the diagonal) and the nearest other UAV
        for i in range(n_uav):
            nearest = math.inf
            for j in range(n_uav):
                if i == j:
                    pair[b, i, j] = math.inf
                else:
                    for k in range(3):
                        diff[k] = z[b, i, k] - z[b, j, k]
                    pair[b, i, j] = math.sqrt(_dot(diff, diff))
                nearest = pair[b, i, j] if j == 0 else min(nearest, pair[b, i, j])
            separation[b, i] = nearest if nearest <= radius else math.inf
        # nearest obstacle surface (horizontal; negative inside)
        for i in range(n_uav):
            best = math.inf
            for o in range(n_obs):
                rx = z[b, i, 0] - centres[o, 0]
                ry = z[b, i, 1] - centres[o, 1]
                value = math.sqrt(rx * rx + ry * ry) - radii[o]
                best = value if o == 0 else min(best, value)
            surface[b, i] = best
        # formation term: moments about the swarm's mean anchored state
        for i in range(n_uav):
            for k in range(6):
                a[i, k] = z[b, i, k] - sign * offsets[i, k]
        for k in range(6):
            total = a[0, k]
            for i in range(1, n_uav):
                total = total + a[i, k]
            mean[k] = total / n_uav
        for i in range(n_uav):
            for k in range(6):
                centred[i, k] = a[i, k] - mean[k]
        for i in range(n_uav):
            b_sq[i] = _dot(centred[i], centred[i])
        for i in range(n_uav):
            degree = adjacency[b, i, 0]
            for j in range(1, n_uav):
                degree = degree + adjacency[b, i, j]
            for k in range(6):
                acc = 0.0
                for j in range(n_uav):
                    acc = acc + adjacency[b, i, j] * centred[j, k]
                h_b[k] = acc
            h_bb = _dot(adjacency[b, i], b_sq)  # contiguous operands: numpy's two lanes
            formation[b, i] = q * (degree * b_sq[i] - 2.0 * _dot(centred[i], h_b) + h_bb)
            energy[b, i] = r * _dot(u_n[b, i], u_n[b, i])
            for k in range(3):
                diff[k] = z[b, i, 3 + k] - reference[b, i, k]
            velocity[b, i] = n_w * _dot(diff, diff)
            total = 0.0
            for j in range(n_uav):
                g = max(d_s - pair[b, i, j], 0.0)
                weighted = g * g * (0.0 if i == j else 1.0)
                total = weighted if j == 0 else total + weighted
            gap[b, i] = s_w * total
            obstacle[b, i] = 0.0
            if o_w > 0.0:
                g = max(c_o - surface[b, i], 0.0)
                obstacle[b, i] = o_w * (g * g)
            collision[b, i] = separation[b, i] < uav_distance or surface[b, i] < obstacle_distance
            for k in range(3):
                est = 0.0
                if observer_on:
                    est = d_hat[b, i, k] if without_s0 else d_hat[b, i, k] + s0[b, i, k]
                estimate[b, i, k] = est
        # the full observation (core/observation.py), scaled and clipped slot by slot
        for i in range(n_uav):
            for k in range(3):
                raw[k] = z[b, i, 3 + k]
                raw[3 + k] = z[b, i, 3 + k] - reference[b, i, k]
                raw[6 + k] = reference[b, i, k]
                raw[9 + k] = estimate[b, i, k]
            raw[12] = t[b] / duration
            raw[13] = 1.0 if avoiding[b, i] else 0.0
            if n_obs:
                best = 0
                best_value = math.inf
                for o in range(n_obs):
                    rx = centres[o, 0] - z[b, i, 0]
                    ry = centres[o, 1] - z[b, i, 1]
                    value = math.sqrt(rx * rx + ry * ry) - radii[o]
                    if o == 0 or value < best_value:
                        best, best_value = o, value
                raw[14] = centres[best, 0] - z[b, i, 0]
                raw[15] = centres[best, 1] - z[b, i, 1]
                raw[16] = best_value
                raw[17] = 1.0
            else:
                raw[14] = raw[15] = raw[16] = raw[17] = 0.0
            raw[18] = separation[b, i]
            for m in range(n_uav - 1):
                j = others[i, m]
                base = 19 + 7 * m
                raw[base] = adjacency[b, i, j]
                for k in range(6):
                    raw[base + 1 + k] = a[j, k] - a[i, k]
            for k in range(dim):
                obs[b, i, k] = np.float32(_clip(raw[k] / scale[k], low[k], high[k]))


advance = njit(_advance)
finish = njit(_finish)


def platform_agrees() -> bool:
    """Whether numpy on this machine sums as the kernels do (its einsum's two-lane sums of
    products, its sequential reductions over short axes), on a few random vectors."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(16, 19)) * np.exp(rng.normal(size=(16, 19)) * 4)
    y = rng.normal(size=(16, 19)) * np.exp(rng.normal(size=(16, 19)) * 4)
    for k in (2, 3, 5, 6, 9, 19):
        expected = np.einsum("...k,...k->...", x[:, :k], y[:, :k])
        ours = np.array([_dot(x[m, :k].copy(), y[m, :k].copy()) for m in range(16)])
        if not np.array_equal(ours, expected):
            return False
    rows = x[None, :5, :6].copy()
    sequential = (((rows[:, 0] + rows[:, 1]) + rows[:, 2]) + rows[:, 3]) + rows[:, 4]
    h = (rng.random((1, 5, 5)) < 0.6).astype(float)
    h_b = np.zeros((1, 5, 6))
    for j in range(5):
        h_b = h_b + h[:, :, j, None] * rows[:, None, j]
    return bool(
        np.array_equal(np.add.reduce(rows, axis=1), sequential)
        and np.array_equal(np.einsum("bij,bj...->bi...", h, rows), h_b)
    )
