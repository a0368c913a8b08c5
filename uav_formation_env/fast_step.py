"""B = 1 fast path of :class:`~uav_formation_env.sim.FormationSim` (numba, the ``[fast]`` extra).

At a batch of one a simulator step is ~200 numpy calls on arrays of 5 x 3 values: the cost is
dispatch, not arithmetic. This module runs the whole step as two compiled kernels: the
dynamics (input clip, observer compensation, eq. 21 disturbance from the same noise block, the
observer's inner ticks, the ZOH step) and the finish (topology outputs with no obstacle in play,
distances, the stage cost J_i's terms, the full observation). The batched numpy path stays the
one definition: the kernels repeat its operations in the same order (numpy's two-lane sums of
products, its sequential reductions; no fast-math), so they give the same numbers bit for bit,
which ``tests/test_fast_step.py`` checks over whole episodes, and :func:`_platform_agrees`
checks numpy's summation order on this machine before the path is used.

What the kernels do not cover runs through the batched code: a step in which an obstacle is
active or some UAV is within an armed obstacle's detection radius calls
:func:`~uav_formation_env.core.topology.update_topology` between the two kernels; scenarios with
scene distributions, turn preview, corner blend, route return, counter noise, a sensing grid or
the torch backend never take the fast path (:func:`attach` returns None). Set
``UAV_FORMATION_NO_NUMBA=1`` to switch it off.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uav_formation_env.core import observer_kernel, topology
from uav_formation_env.core.cost import CostTerms
from uav_formation_env.core.observation import _layout, others_index
from uav_formation_env.core.observer import ObserverState
from uav_formation_env.core.obstacles import detection_sq, obstacle_arrays
from uav_formation_env.core.proximity import GRID_MIN_UAVS
from uav_formation_env.core.reference import schedule_arrays

AVAILABLE = observer_kernel.AVAILABLE
_TIME_TOL = 1e-9  # core.reference's tolerance of "t <= times[k]" [s]


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
    sensing radius (inf: none), observer on, estimate without s0).
    """
    batch, n_uav = z.shape[0], z.shape[1]
    n_obs = radii.shape[0]
    q, r, n_w, s_w, d_s, o_w, c_o = (
        weights[0], weights[1], weights[2], weights[3], weights[4], weights[5], weights[6]
    )  # fmt: skip
    duration, sign, uav_distance, radius = par[0], par[1], par[2], par[3]
    observer_on, without_s0 = par[4] != 0.0, par[5] != 0.0
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
            collision[b, i] = separation[b, i] < uav_distance or surface[b, i] < 0.0
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


_advance = njit(_advance)
_finish = njit(_finish)


# ------------------------------------------------------------------------------------------------
# the simulator's side
# ------------------------------------------------------------------------------------------------


def _platform_agrees() -> bool:
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


_AGREES: list[bool] = []


def supported(scenario: Any, backend: str, noise: str, n_uav: int) -> bool:
    """Whether a simulator of these settings can take the fast path (see the module docstring)."""
    avoidance = scenario.avoidance
    radius = scenario.observation.sensing_radius
    if not (
        AVAILABLE
        and backend == "numpy"
        and noise == "generator"
        and scenario.scene is None
        and avoidance.turn_preview == 0.0
        and avoidance.turn_blend == 0.0
        and avoidance.route_gain == 0.0
        and (radius is None or n_uav < GRID_MIN_UAVS)
        and n_uav >= 2
    ):
        return False
    if not _AGREES:
        _AGREES.append(_platform_agrees())
    return _AGREES[0]


class FastStep:
    """Steps a :class:`~uav_formation_env.sim.FormationSim` with the kernels, leaving it in the
    state its own :meth:`~uav_formation_env.sim.FormationSim.step` would (the same arrays, bit
    for bit), and keeps the step's full observation for the episode layer.

    Args:
        sim: the simulator (numpy backend, a supported scenario).
        result_type: the simulator's ``StepResult`` class.
    """

    def __init__(self, sim: Any, result_type: type) -> None:
        cfg = sim.scenario
        self.sim = sim
        self._result_type = result_type
        n_uav, dist, obs_cfg = sim.n_uav, sim.disturbance, cfg.observer
        d_cfg = dist.config
        self._signed = np.where(np.arange(1, n_uav + 1) % 2 == 1, -1.0, 1.0) * d_cfg.amplitude
        self._wind = np.asarray(d_cfg.wind, dtype=float)
        self._gusty = dist.gust_dim > 0
        self._waves = self._wave_table(cfg.n_steps + 1)
        self._advance_par = np.array([
            sim.u_max, sim.dt, obs_cfg.enabled, obs_cfg.estimate_without_s0, d_cfg.noise_scale,
            dist.uniform_dim, dist.gust_dim, dist.gust_decay, dist._innovation_scale,
            obs_cfg.substeps, obs_cfg.literal_sign_law,
            obs_cfg.lambda1 == 2.0 and obs_cfg.lambda2 == 1.5, cfg.avoidance.rearm,
            d_cfg.model == "paper",
        ], dtype=float)  # fmt: skip
        c = obs_cfg
        self._gains = np.array([c.pi1, c.lambda1, c.pi2, c.lambda2, c.eta, c.rho])
        self._centres = np.ascontiguousarray(obstacle_arrays(cfg.avoidance)[0]).reshape(-1, 2)
        self._r_detect_sq = np.asarray(detection_sq(cfg.avoidance), dtype=float).reshape(-1)
        self._radii = np.asarray(sim.obstacle_radii, dtype=float)
        self._times, self._velocities = schedule_arrays(cfg.schedule)
        self._h0 = np.asarray(sim.base_adjacency, dtype=float)
        self._offsets = np.asarray(sim.offsets, dtype=float)
        w = cfg.cost
        self._weights = np.array([
            w.q, w.r, w.n, w.separation, w.separation_distance, w.obstacle, w.obstacle_margin,
        ], dtype=float)  # fmt: skip
        radius = cfg.observation.sensing_radius
        self._finish_par = np.array([
            cfg.duration, -1.0 if cfg.formation.mirrored_offsets else 1.0,
            cfg.collision.uav_distance, math.inf if radius is None else radius,
            obs_cfg.enabled, obs_cfg.estimate_without_s0,
        ], dtype=float)  # fmt: skip
        self._layout = (*_layout(n_uav)[:3], np.ascontiguousarray(others_index(n_uav)))
        self._full_observation = cfg.observation.kind == "full"
        self._observation: tuple[Any, np.ndarray] | None = None

    def _wave_table(self, count: int) -> np.ndarray:
        """(count, 3) eq. 21's [sin, cos, sin] at steps 0..count-1, computed as
        :func:`~uav_formation_env.core.disturbances.paper_sinusoid` computes them."""
        period = self.sim.disturbance.config.period
        phase = 2.0 * np.pi * (np.arange(count) * self.sim.dt) / period
        waves = np.empty((count, 3))
        waves[:, 0] = np.sin(phase)
        waves[:, 1] = np.cos(phase)
        waves[:, 2] = waves[:, 0]
        return waves

    def step(self, u_n: np.ndarray) -> Any:
        """One step of every copy from the (B, N, 3) finite formation input; the simulator's
        new :class:`StepResult`."""
        sim = self.sim
        batch, n_uav = sim.batch_size, sim.n_uav
        n_obs = self._radii.shape[0]
        if (sim.steps[0] if batch == 1 else sim.steps.max()) >= len(self._waves):
            self._waves = self._wave_table(2 * len(self._waves))  # stepped past the duration
        empty = np.empty
        u, d, z, t = (
            empty((batch, n_uav, 3)),
            empty((batch, n_uav, 3)),
            np.empty_like(sim.z),
            empty(batch),
        )
        u_clipped, u_d = empty((batch, n_uav, 3)), empty((batch, n_uav, 3))
        old = sim.observer
        new = ObserverState(*(empty((batch, n_uav, 3)) for _ in range(4)))
        gust = empty((batch, n_uav, 3)) if self._gusty else sim.gust
        busy = _advance(
            u_n, sim.z, old.v_hat, old.s0, old.d_hat, old.e_prev, sim.noise, sim.noise_pos,
            sim.gust, self._waves, sim.steps, self._signed, self._wind, self._advance_par,
            self._gains, sim.topology.status, self._centres, self._r_detect_sq, u_clipped, u_d,
            u, d, gust, new.v_hat, new.s0, new.d_hat, new.e_prev, z, t,
        )  # fmt: skip
        sim.gust, sim.observer, sim.z, sim.t = gust, new, z, t
        sim._advance_noise()
        if busy:
            sim.topology, out = topology.update_topology(
                sim.topology, z[..., :3], z[..., 3:], t, sim.scenario.avoidance, sim.schedule,
                sim.base_adjacency, None, sim.route_start,
            )  # fmt: skip
            adjacency, reference, avoiding = out.adjacency, out.reference_velocity, out.avoiding
            groups, activated, restored = out.groups, out.activated, out.restored
            correction = out.route_correction
        else:
            adjacency, reference = empty((batch, n_uav, n_uav)), empty((batch, n_uav, 3))
            groups = np.zeros((batch, n_uav), dtype=np.int64)
            avoiding = np.zeros((batch, n_uav), dtype=bool)
            activated = np.zeros((batch, n_obs), dtype=bool)
            restored = np.zeros((batch, n_obs), dtype=bool)
            correction = np.zeros((batch, 3))
        pair = empty((batch, n_uav, n_uav))
        separation, surface = empty((batch, n_uav)), empty((batch, n_uav))
        terms = [empty((batch, n_uav)) for _ in range(5)]
        collision = empty((batch, n_uav), dtype=bool)
        estimate = empty((batch, n_uav, 3))
        obs = empty((batch, n_uav, self._layout[0].shape[0]), dtype=np.float32)
        _finish(
            z, u_clipped, t, not busy, avoiding, self._h0, self._times, self._velocities,
            self._offsets, self._centres, self._radii, new.d_hat, new.s0, self._weights,
            self._finish_par, *self._layout, adjacency, reference, pair, separation, surface,
            *terms, collision, estimate, obs,
        )  # fmt: skip
        formation, energy, velocity, gap, obstacle = terms
        terminal = np.zeros((batch, n_uav))
        result = self._result_type(
            z=z.copy(), u_n=u_clipped, u_d=u_d, u_applied=u, disturbance=d, estimate=estimate,
            adjacency=adjacency, groups=groups, reference_velocity=reference, avoiding=avoiding,
            cost=CostTerms(formation, energy, terminal, velocity, gap, obstacle),
            t=t.copy(), step=sim.steps.copy(), truncated=sim.steps >= sim._n_steps,
            min_separation=separation, obstacle_distance=surface, collision=collision,
            activated=activated, restored=restored, route_correction=correction,
        )  # fmt: skip
        sim._pair_of = (result.z, pair)
        sim.last = result
        if self._full_observation:
            self._observation = (result, obs)
        return result

    def observation(self, result: Any) -> np.ndarray | None:
        """The (B, N, dim) float32 full observation of ``result`` if this path computed it."""
        cached = self._observation
        return cached[1] if cached is not None and cached[0] is result else None


def attach(sim: Any, result_type: type) -> FastStep | None:
    """A :class:`FastStep` for ``sim``, or None where the fast path does not apply."""
    if not supported(sim.scenario, sim.backend, sim.noise_source, sim.n_uav):
        return None
    return FastStep(sim, result_type)
