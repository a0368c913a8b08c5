"""The compiled step of :class:`~uav_formation_env.sim.FormationSim` (numba, the ``[fast]`` extra).

At a batch of one a simulator step is ~200 numpy calls on arrays of 5 x 3 values: the cost is
dispatch, not arithmetic. This module runs the whole step as the two compiled kernels of
:mod:`uav_formation_env.fast_kernels`: the dynamics (input clip, observer compensation, eq. 21
disturbance from the same noise block, the observer's inner ticks, the ZOH step) and the finish
(topology outputs with no obstacle in play, distances, the stage cost J_i's terms, the full
observation). The batched numpy path stays the one definition: the kernels repeat its
operations in the same order, so they give the same numbers bit for bit, which
``tests/test_fast_step.py`` checks over whole episodes, and
:func:`~uav_formation_env.fast_kernels.platform_agrees` checks numpy's summation order on this
machine before the path is used.

What the kernels do not cover runs through the batched code: a step in which an obstacle is
active or some UAV is within an armed obstacle's detection radius calls
:func:`~uav_formation_env.core.topology.update_topology` between the two kernels; scenarios with
scene distributions, turn preview, corner blend, route return, counter noise, a sensing grid or
the torch backend never take the fast path (:func:`attach` returns None). B > 1 copies take it
too (a loop over copies in each kernel). Set ``UAV_FORMATION_NO_NUMBA=1`` to switch it off.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uav_formation_env.core import topology
from uav_formation_env.core.cost import CostTerms
from uav_formation_env.core.observation import _layout, others_index
from uav_formation_env.core.observer import ObserverState
from uav_formation_env.core.obstacles import detection_sq, obstacle_arrays
from uav_formation_env.core.proximity import GRID_MIN_UAVS
from uav_formation_env.core.reference import schedule_arrays
from uav_formation_env.fast_kernels import AVAILABLE, advance, finish, platform_agrees

__all__ = ["AVAILABLE", "FastStep", "attach", "supported"]


# ------------------------------------------------------------------------------------------------
# the simulator's side
# ------------------------------------------------------------------------------------------------


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
        _AGREES.append(platform_agrees())
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
        self._radii = np.array([o.radius for o in cfg.avoidance.obstacles], dtype=float)
        self._times, self._velocities = schedule_arrays(cfg.schedule)
        self._h0 = np.asarray(cfg.formation.adjacency, dtype=float)
        self._offsets = np.asarray(cfg.formation.slot_offsets, dtype=float)
        w = cfg.cost
        self._weights = np.array([
            w.q, w.r, w.n, w.separation, w.separation_distance, w.obstacle, w.obstacle_margin,
        ], dtype=float)  # fmt: skip
        radius = cfg.observation.sensing_radius
        self._finish_par = np.array([
            cfg.duration, 1.0,  # sim.offsets are the slots (FormationConfig.slot_offsets)
            cfg.collision.uav_distance, math.inf if radius is None else radius,
            obs_cfg.enabled, obs_cfg.estimate_without_s0, cfg.collision.obstacle_distance,
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
        busy = advance(
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
                sim.base_adjacency, sim.obstacles, sim.route_start,
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
        finish(
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
