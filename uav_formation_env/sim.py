"""``FormationSim``: B copies of a scenario stepped together on the batched core.

The simulator owns the state (UAV states, observer, gusts, topology, time, random streams) and
composes the pure core functions; it holds no formula of its own. Each copy has its own
``np.random.Generator`` seeded at reset, and draws its disturbance noise in fixed blocks of
:data:`NOISE_BLOCK` steps, so copy ``b`` of a batch reproduces a one-copy simulation seeded alike
bit for bit, whatever B is and whenever other copies reset.

Order of one control step (docs/model.md §1.4, §3.3, §3.4, §7):

1. ``u_n`` clipped to ±u_max; ``u_d = -(d_hat + s0)`` if the observer is on, else 0;
   applied ``u = clip(u_n + u_d, ±u_max)``.
2. Disturbance ``d`` of the step (held), ``a = u + d``.
3. Observer over its inner ticks on the exact velocity samples; plant ZOH step over δ.
4. ``t += δ``; topology update at the new positions (adjacency, groups, reference velocity).
5. Stage cost of J_i at the new state with the applied ``u_n`` (the reward is minus its total).

Backends (docs/architecture.md, "Backends"): :class:`~uav_formation_env.sim_options.SimOptions`
``backend="numpy"`` (default) or ``"torch"`` on any device. The state and every array of a
:class:`StepResult` live on the backend's device; the core functions are the same array-API code
on both. Randomness stays on the host: each copy's numpy
Generator draws its scene, start and noise blocks exactly as on numpy, and the drawn values are
moved to the device, so a seed names the same episode on both backends. With ``noise="counter"``
the disturbance noise of step k is instead a counter-based draw
(:mod:`~uav_formation_env.core.counter_rng`) keyed by the copy's seed and counted by k, computed
on the device each step (no host loop over copies); numpy and torch draw the same numbers.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, is_dataclass, replace
from types import ModuleType

import numpy as np

from uav_formation_env import fast_step
from uav_formation_env.config import Scenario
from uav_formation_env.core import counter_rng, topology
from uav_formation_env.core.array_api import (
    amin,
    device,
    namespace,
    namespace_of_backend,
    to_numpy,
)
from uav_formation_env.core.array_api import copy as copy_array
from uav_formation_env.core.cost import CostTerms, stage_cost
from uav_formation_env.core.disturbances import CopyDisturbance, Disturbance
from uav_formation_env.core.dynamics import zoh_step
from uav_formation_env.core.initial import formation_positions, initial_positions
from uav_formation_env.core.observer import (
    ObserverState,
    compensation,
    disturbance_estimate,
    observer_init,
    observer_step_held,
)
from uav_formation_env.core.obstacles import ObstacleField, obstacle_field
from uav_formation_env.core.proximity import SensedPairs, nearest_distance, uav_pairs
from uav_formation_env.core.reference import CopySchedules, Schedule, blend_offset, copy_schedules
from uav_formation_env.core.tracing import call_compiled
from uav_formation_env.scenes import (
    max_gust_std,
    max_obstacles,
    max_route_legs,
    n_uav_range,
    scene_of_seed,
)
from uav_formation_env.seeding import check_seed
from uav_formation_env.sim_options import SimOptions

NOISE_BLOCK = 100  # control steps of disturbance noise drawn per Generator call

SeedLike = int | Sequence[int] | None


@dataclass
class StepResult:
    """What one step (or a reset) produced; arrays are batched over B copies and N UAVs."""

    z: np.ndarray  # (B, N, 6) state after the step [m, m/s]
    u_n: np.ndarray  # (B, N, 3) formation input after clipping [m/s^2]
    u_d: np.ndarray  # (B, N, 3) observer compensation [m/s^2]
    u_applied: np.ndarray  # (B, N, 3) clip(u_n + u_d) [m/s^2]
    disturbance: np.ndarray  # (B, N, 3) d held over the step [m/s^2]
    estimate: np.ndarray  # (B, N, 3) observer estimate after the step [m/s^2]
    adjacency: np.ndarray  # (B, N, N) h_ij at the new time
    groups: np.ndarray  # (B, N) sub-formation ids
    reference_velocity: np.ndarray  # (B, N, 3) v^d at the new time [m/s]
    avoiding: np.ndarray  # (B, N) following an avoidance reference
    cost: CostTerms  # (B, N) stage terms of J_i
    t: np.ndarray  # (B,) time after the step [s]
    step: np.ndarray  # (B,) steps taken since reset
    truncated: np.ndarray  # (B,) episode reached the scenario duration
    min_separation: np.ndarray  # (B, N) distance to the nearest other UAV [m]
    obstacle_distance: np.ndarray  # (B, N) distance to the nearest obstacle surface [m]
    collision: np.ndarray  # (B, N) too close to a UAV or inside an obstacle
    activated: np.ndarray  # (B, O) obstacle became active at this step
    restored: np.ndarray  # (B, O) obstacle finished at this step
    route_correction: np.ndarray  # (B, 3) route-return term of the references [m/s]


def _seeds_for(seed: SeedLike, count: int) -> list[int | None]:
    if seed is None or isinstance(seed, int | np.integer | bool | float | str):
        first = check_seed(seed)
        return [None if first is None else first + b for b in range(count)]
    seeds = [check_seed(s, f"seeds[{k}]") for k, s in enumerate(seed)]
    if len(seeds) != count:
        raise ValueError(f"expected {count} seeds (one per reset copy), got {len(seeds)}")
    return seeds


def _where_batch(mask, new, old):
    """Fieldwise ``where(mask)`` over the leading batch axis of two dataclasses of arrays (numpy
    or torch; ``mask`` (B,) bool of the same library)."""
    xp = namespace(mask)
    out = {}
    for f in fields(old):
        a, b = getattr(new, f.name), getattr(old, f.name)
        if is_dataclass(b):
            out[f.name] = _where_batch(mask, a, b)
        else:
            m = xp.reshape(mask, mask.shape + (1,) * (b.ndim - 1))
            out[f.name] = xp.where(m, a, b)
    return replace(old, **out)


def _host(values, dtype) -> np.ndarray:
    """A mask or index array given as numpy, a list or a torch tensor, as a numpy array."""
    if not isinstance(values, np.ndarray | list | tuple):
        values = to_numpy(values)
    return np.asarray(values, dtype=dtype)


def _scene_n_uav(scenario: Scenario, n_uav: int | None) -> int:
    """The N of a simulator of ``scenario`` (see :class:`FormationSim`)."""
    low, high = n_uav_range(scenario)
    if n_uav is None:
        if low != high:
            raise ValueError(
                f"scenario {scenario.name!r} draws N per reset in {low}..{high}; a simulator has "
                "one N: pass n_uav (resets whose seed draws another N are refused)"
            )
        return low
    if not isinstance(n_uav, int | np.integer) or not low <= n_uav <= high:
        span = f"{low}" if low == high else f"in {low}..{high}"
        raise ValueError(f"n_uav must be an integer {span} (the scenario's N), got {n_uav!r}")
    return int(n_uav)


def measured_distances(cfg: Scenario, z, pair, obstacles: ObstacleField) -> tuple:
    """Nearest-UAV distance and nearest obstacle-surface distance of the states ``z``, each
    (B, N) [m] (see :meth:`FormationSim.distances`)."""
    p = z[..., :3]
    if obstacles.count == 0:
        surface = namespace(p).full(p.shape[:2], math.inf, dtype=p.dtype, device=device(p))
    else:  # padding obstacles are 1e9 m away: never the nearest of a UAV on its route
        centre = topology.obstacle_distances(p, obstacles)
        surface = amin(centre - obstacles.radii[:, None], axis=-1)
    return nearest_distance(pair, cfg.observation.sensing_radius), surface


def measure_state(
    cfg: Scenario,
    z,
    observer: ObserverState,
    u_n,
    out: topology.TopologyOutput,
    offsets,
    obstacles: ObstacleField,
) -> tuple:
    """What the states ``z`` (B, N, 6) measure after the topology update ``out``: the pair
    distances, the nearest-UAV and obstacle-surface distances (B, N) [m], the stage cost terms
    of J_i with the input ``u_n``, the collision flags (B, N) and the observer's estimate
    (B, N, 3) [m/s^2]."""
    # one set of pair distances for the separation term, the nearest-UAV distance and the
    # observation: all pairs, or those within the sensing radius (linear in N)
    pair = uav_pairs(z[..., :3], cfg.observation.sensing_radius)
    separation, obstacle_distance = measured_distances(cfg, z, pair, obstacles)
    cost = stage_cost(
        z,
        u_n,
        out.reference_velocity,
        out.adjacency,
        offsets,
        cfg.cost,
        pair_distance=pair,
        obstacle_surface=obstacle_distance,
    )
    collision = (separation < cfg.collision.uav_distance) | (
        obstacle_distance < cfg.collision.obstacle_distance
    )
    if cfg.observer.enabled:
        estimate = disturbance_estimate(observer, cfg.observer)
    else:
        estimate = namespace(u_n).zeros_like(u_n)
    return pair, separation, obstacle_distance, cost, collision, estimate


class FormationSim:
    """B scenario copies stepped together.

    A scenario with a scene distribution (``scenario.scene``) draws each copy's scene (formation,
    graph, obstacles, disturbance, start box) at every reset from the copy's generator, before
    the start positions: a seed names the scene and the episode, whatever the batch. The drawn
    scenes are :attr:`scenes`; the per-copy arrays :attr:`offsets` (B, N, 6),
    :attr:`base_adjacency` (B, N, N) and :attr:`obstacles` hold them for the batched core.

    Args:
        scenario: the validated scenario.
        batch_size: number of copies B.
        n_uav: N of a distribution that draws N per reset (every copy of a simulator has the same
            N; a reset whose seed draws another N raises ValueError and changes nothing).
        options: the array library, device, compilation and noise source
            (:class:`~uav_formation_env.sim_options.SimOptions`; None: numpy on the CPU).
    """

    def __init__(
        self,
        scenario: Scenario,
        batch_size: int = 1,
        n_uav: int | None = None,
        options: SimOptions | None = None,
    ) -> None:
        if not isinstance(batch_size, int | np.integer) or batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        options = SimOptions() if options is None else options
        if not isinstance(options, SimOptions):
            raise TypeError(f"options must be a SimOptions, got {type(options).__name__}")
        self.options = options
        self.noise_source = options.noise
        self.backend = options.backend
        self.device = options.resolved_device()
        self.scenario = scenario
        self.batch_size = int(batch_size)
        self.n_uav = _scene_n_uav(scenario, n_uav)
        self.dt = scenario.dynamics.dt
        self.u_max = scenario.dynamics.u_max
        B, N = self.batch_size, self.n_uav
        self.scenes: list[Scenario] = [scenario] * B  # the concrete scenario of each copy
        # every copy's scene as per-copy arrays, written at reset (a fixed scenario is a scene
        # distribution of one point)
        self.offsets = np.zeros((B, N, 6))  # slot offsets of each copy [m, m/s]
        self.base_adjacency = np.zeros((B, N, N))  # H0 of each copy
        empty = replace(scenario.avoidance, obstacles=())
        self.obstacles: ObstacleField = obstacle_field([empty] * B, max_obstacles(scenario))
        # the noise layout has gust columns whenever some draw may have gusts
        disturbance = replace(scenario.disturbance, gust_std=max_gust_std(scenario))
        self.copy_disturbance = CopyDisturbance.of(disturbance, B)
        self._written: list[Scenario | None] = [None] * B  # the scene in each copy's arrays
        self.disturbance = Disturbance(disturbance, N, self.dt)
        # the preset schedule: the scenario's, or one drawn per copy (scene.route)
        self.schedule: Schedule = scenario.schedule
        legs = max_route_legs(scenario)
        if legs is not None:
            self.schedule = copy_schedules([scenario.schedule] * B, legs)
        self._rows = np.arange(self.batch_size)
        self._n_steps = scenario.n_steps
        # The state of every copy, declared here and (re)initialised per copy by reset().
        self._rngs = [np.random.default_rng() for _ in range(B)]  # per copy: disturbance noise
        self._seed_streams: list[np.random.Generator | None] = [None] * B  # follow-up seeds
        self.z = np.zeros((B, N, 6))  # UAV states [m, m/s]
        self.gust = np.zeros((B, N, 3))  # Gauss-Markov gust [m/s^2]
        self.noise = np.zeros((B, NOISE_BLOCK, N, self.disturbance.noise_dim))  # drawn noise
        self.noise_pos = np.zeros(B, dtype=np.int64)  # next unused noise step per copy
        self.noise_keys = np.zeros((B, 2), dtype=np.int64)  # noise="counter": per-copy keys
        self._noise_left = NOISE_BLOCK  # steps until some copy needs a new noise block
        self.t = np.zeros(B)  # time since reset [s]
        self.route_start = np.zeros((B, 3))  # formation centroid at t = 0: the route's start [m]
        self.steps = np.zeros(B, dtype=np.int64)  # control steps since reset
        self.observer: ObserverState = observer_init(self.z[..., 3:])
        self.topology = topology.init_topology(B, N, self.obstacle_radii.shape[-1])
        self.last: StepResult | None = None  # None until the first reset
        # the states of the last step's result and their pair distances (see pair_distances_of)
        self._pair_of: tuple[np.ndarray | None, np.ndarray | SensedPairs] = (None, np.zeros(0))
        if self.backend != "numpy":  # everything the step reads, on the device
            for name in ("offsets", "base_adjacency"):
                setattr(self, name, self._put(getattr(self, name)))
            for name in ("z", "gust", "t", "route_start", "steps", "noise_keys"):
                setattr(self, name, self._put(getattr(self, name)))
            self.obstacles = self._put_fields(self.obstacles)
            self.copy_disturbance = self._put_fields(self.copy_disturbance)
            if isinstance(self.schedule, CopySchedules):
                self.schedule = self._put_fields(self.schedule)
            self.observer = self._put_fields(self.observer)
            self.topology = self._put_fields(self.topology)
        # the compiled step of the same numbers (fast_step.py), where it applies
        self.fast_path = fast_step.attach(self, StepResult)
        # SimOptions.compile: _advance through torch.compile, built at the first step
        self._compiled: list = []

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_compiled"] = []  # a compiled function does not pickle; compiled again on use
        return state

    # ------------------------------------------------------------------ backend
    def _put(self, values):
        """A numpy array as an array of this simulator's backend and device (numpy: itself)."""
        if self.backend == "numpy":
            return values
        return self.xp.asarray(np.ascontiguousarray(values), device=self.device)

    @property
    def xp(self) -> ModuleType:
        """The array namespace of :attr:`backend`, looked up (a module does not pickle)."""
        return namespace_of_backend(self.backend)

    def _put_fields(self, data):
        """A dataclass of numpy arrays with every array moved by :meth:`_put` (None: None)."""
        if data is None or self.backend == "numpy":
            return data
        return replace(data, **{f.name: self._put(getattr(data, f.name)) for f in fields(data)})

    # ------------------------------------------------------------------ reset
    def reset(self, seed: SeedLike = None, mask: np.ndarray | None = None) -> StepResult:
        """Start new episodes in all copies, or only in those where ``mask`` is True.

        A copy reset with an explicit seed also starts a stream of follow-up seeds; a later reset
        of that copy with ``seed=None`` takes the next seed of its stream (so a sequence of
        episodes is reproducible from one seed), and a copy never seeded uses fresh entropy.

        Args:
            seed: an int (copy b of the reset copies gets ``seed + b``), one seed (or None) per
                reset copy, or None.
            mask: (B,) bool; None resets every copy (required on the first call).

        Returns:
            The :class:`StepResult` of time 0 (inputs, disturbance and cost terms are zero).
        """
        B, N, cfg = self.batch_size, self.n_uav, self.scenario
        if mask is None:
            mask = np.ones(B, dtype=bool)
        elif self.last is None:
            raise ValueError("the first reset must reset every copy (mask=None)")
        mask = _host(mask, bool)
        if mask.shape != (B,):
            raise ValueError(f"mask must have shape ({B},), got {mask.shape}")
        indices = np.flatnonzero(mask)
        seeds = _seeds_for(seed, len(indices))
        # Draw every copy's scene first and commit only if all fit: a refused reset changes
        # nothing (the follow-up seed streams are advanced on copies).
        draws = []
        for b, s in zip(indices, seeds):
            stream = self._seed_streams[b]
            if s is not None:
                stream = np.random.default_rng(np.random.SeedSequence(s).spawn(1)[0])
            elif stream is not None:
                stream = copy.deepcopy(stream)
                s = int(stream.integers(2**63))
            scene, rng = scene_of_seed(cfg, s)
            if scene.n_uav != N:
                raise ValueError(
                    f"seed {s} draws a scene of {scene.n_uav} UAVs for copy {b}, but this "
                    f"simulator has n_uav={N}"
                )
            draws.append((b, stream, rng, scene))
        # the reset copies' starts, drawn on the host in the same order on every backend
        z = np.empty((len(draws), N, 6))
        gust = np.empty((len(draws), N, 3))
        keys = np.zeros((len(draws), 2), dtype=np.int64)
        for row, (b, stream, rng, scene) in enumerate(draws):
            self._seed_streams[b], self._rngs[b], self.scenes[b] = stream, rng, scene
            initial = scene.initial
            low, high = np.asarray(initial.position_low), np.asarray(initial.position_high)
            if initial.formation_jitter is None:
                z[row, :, :3] = initial_positions(rng, N, low, high, initial.min_spacing)
            else:
                slots = scene.formation.slot_offsets[:, :3]
                centre = (low + high) / 2
                z[row, :, :3] = formation_positions(rng, slots, centre, initial.formation_jitter)
            z[row, :, 3:] = initial.velocity
            if self._written[b] is not scene:
                self._set_scene(b, scene)
            gust[row] = self.disturbance.initial_gust(rng, scene.disturbance.gust_std)
            if self.noise_source == "counter":
                keys[row] = rng.integers(0, 2**32, size=2, dtype=np.int64)
            else:
                self.noise[b] = self.disturbance.draw_noise(rng, NOISE_BLOCK)
        self.noise_pos[mask] = 0
        self._noise_left = NOISE_BLOCK - int(self.noise_pos.max())
        at = self._put(indices)
        self.z[at], self.gust[at] = self._put(z), self._put(gust)
        self.noise_keys[at] = self._put(keys)
        self.route_start[at] = self._put(z[:, :, :3].mean(axis=1))
        self.t[at] = 0.0
        self.steps[at] = 0
        on = self._put(mask)
        self.observer = _where_batch(on, observer_init(self.z[..., 3:]), self.observer)
        self.topology = topology.reset_topology(self.topology, on)
        zeros = self.xp.zeros((B, N, 3), dtype=self.z.dtype, device=self.device)
        result = self._finish(on, (zeros, zeros, zeros, zeros))
        if self.last is not None and not mask.all():
            result = _where_batch(on, result, self.last)
        self.last = result
        return result

    def _check_observer(self, observer: ObserverState | None = None) -> None:
        """A ``ValueError`` naming ``observer.substeps`` where the estimate of ``observer`` (None:
        the simulator's) is not finite."""
        obs_cfg = self.scenario.observer
        observer = self.observer if observer is None else observer
        if obs_cfg.enabled and not bool(self.xp.isfinite(observer.d_hat).all()):
            raise ValueError(
                f"the observer diverged (non-finite estimate at t = {float(self.t.max()):g} "
                f"s): its tick dynamics.dt / observer.substeps = {self.dt / obs_cfg.substeps:g}"
                " s is too long for its gains; raise observer.substeps"
            )

    def _set_scene(self, copy: int, scene: Scenario) -> None:
        """Write a drawn scene into copy ``copy``'s per-copy arrays."""
        self.offsets[copy] = self._put(scene.formation.slot_offsets)
        self.base_adjacency[copy] = self._put(np.asarray(scene.formation.adjacency, dtype=float))
        self.obstacles.set_copy(copy, scene.avoidance)
        self.copy_disturbance.set_copy(copy, scene.disturbance)
        if isinstance(self.schedule, CopySchedules):
            self.schedule.set_copy(copy, scene.schedule)
        self._written[copy] = scene

    # ------------------------------------------------------------------ step
    def step(self, u_n: np.ndarray) -> StepResult:
        """Advance every copy by one control step δ.

        Args:
            u_n: (B, N, 3) formation input [m/s^2]; finite values, clipped to ±u_max. An array of
                the simulator's backend (a numpy array is moved to a torch simulator's device).

        Returns:
            The :class:`StepResult` after the step.
        """
        if self.last is None:
            raise RuntimeError("call reset() before step()")
        xp = self.xp
        if self.backend == "numpy" or isinstance(u_n, np.ndarray | list | tuple):
            u_n = self._put(np.asarray(u_n, dtype=float))
        else:
            u_n = xp.asarray(u_n, dtype=self.z.dtype, device=self.device)
        expected = (self.batch_size, self.n_uav, 3)
        if tuple(u_n.shape) != expected:
            raise ValueError(f"u_n must have shape {expected}, got {tuple(u_n.shape)}")
        if not bool(xp.isfinite(u_n).all()):  # the method: numpy's xp.all adds a Python layer
            raise ValueError("u_n contains NaN or infinite values")
        if self.fast_path is not None:
            result = self.fast_path.step(u_n)
            self._check_observer()
            return result
        # host noise blocks are read here; counter draws are computed inside the step
        noise = None if self.noise_source == "counter" else self._step_noise()
        if self.options.compile:  # the whole step as one graph of torch.compile
            # one memory layout of every input from step to step (no recompilation), and the
            # velocities apart from the positions (the compiled loops vectorise contiguous arrays)
            self.topology = replace(
                self.topology,
                **{
                    f.name: getattr(self.topology, f.name).contiguous()
                    for f in fields(self.topology)
                },
            )
            velocity = self.z[..., 3:].contiguous()
            outcome = call_compiled(self._compiled, self._advance, u_n, noise, velocity)
        else:
            outcome = self._advance(u_n, noise)
        z, gust, observer, steps, t, new_topology, result, pair = outcome
        self._check_observer(observer)
        self.z, self.gust, self.observer, self.steps, self.t = z, gust, observer, steps, t
        self.topology, self._pair_of = new_topology, (result.z, pair)
        self._advance_noise()
        self.last = result
        return result

    def _advance(self, u_n, noise=None, velocity=None) -> tuple:
        """One control step from the current state, which it leaves unchanged: the new state
        ``(z, gust, observer, steps, t, topology)``, the :class:`StepResult` and the pair
        distances of the new positions.

        Args:
            u_n: (B, N, 3) formation input [m/s^2].
            noise: (B, N, noise_dim) the step's standard noise; None: :meth:`_step_noise`.
            velocity: the velocities of the state (B, N, 3) [m/s] as a contiguous array (the
                compiled step's loops vectorise those only); None: read from the state.
        """
        xp, obs_cfg = self.xp, self.scenario.observer
        noise = self._step_noise() if noise is None else noise
        # minimum(maximum(.)) is clip for finite values, without numpy's Python wrappers
        u_max = self.u_max
        u_n = xp.minimum(xp.maximum(u_n, -u_max), u_max)
        u_d = compensation(self.observer, obs_cfg) if obs_cfg.enabled else xp.zeros_like(u_n)
        u = xp.minimum(xp.maximum(u_n + u_d, -u_max), u_max)
        d, gust = self.disturbance.evaluate(self.t, noise, self.gust, self.copy_disturbance)
        a = u + d
        observer = self.observer
        if obs_cfg.enabled:
            v0 = self.z[..., 3:] if velocity is None else velocity
            observer = observer_step_held(observer, v0, a, u, self.dt, obs_cfg)
        z = zoh_step(self.z, a, self.dt)
        steps = self.steps + 1
        # steps x dt: no drift from repeated addition (torch: int x float would be float32)
        t = (steps if self.backend == "numpy" else xp.astype(steps, z.dtype)) * self.dt
        new_topology, result, pair = self._outcome(z, t, steps, observer, (u_n, u_d, u, d))
        return z, gust, observer, steps, t, new_topology, result, pair

    def _step_noise(self):
        """(B, N, noise_dim) the standard noise of this step: from the host blocks, or counter
        draws keyed by each copy's key and counted by its step k (U[0, 1) columns with word
        (k, 0, 0), N(0, 1) columns with (k, 1, 0))."""
        if self.noise_source != "counter":
            return self._put(self.noise[self._rows, self.noise_pos])
        xp, disturbance, keys = self.xp, self.disturbance, self.noise_keys
        zero = xp.zeros_like(self.steps)
        parts = [self.z[..., :0]]  # (B, N, 0): the noise of a layout without noise columns
        if disturbance.uniform_dim:
            words = xp.stack((self.steps, zero, zero), axis=1)
            size = (self.n_uav, disturbance.uniform_dim)
            parts.append(counter_rng.uniform(keys, words, size))
        if disturbance.gust_dim:
            words = xp.stack((self.steps, zero + 1, zero), axis=1)
            size = (self.n_uav, disturbance.gust_dim)
            parts.append(counter_rng.standard_normal(keys, words, size))
        return xp.concat(parts, axis=-1)

    def _advance_noise(self) -> None:
        if self.noise_source == "counter":
            return
        self.noise_pos += 1
        # steps until the most advanced copy runs out of noise: no array reduction per step
        self._noise_left -= 1
        if self._noise_left <= 0:
            for b in np.flatnonzero(self.noise_pos >= NOISE_BLOCK):
                self.noise[b] = self.disturbance.draw_noise(self._rngs[b], NOISE_BLOCK)
                self.noise_pos[b] = 0
            self._noise_left = NOISE_BLOCK - int(self.noise_pos.max())

    def _finish(self, mask, inputs: tuple) -> StepResult:
        """The result of the current state (after a reset of the ``mask`` copies): topology
        update, costs and distances; ``inputs``: ``(u_n, u_d, u, d)``, each (B, N, 3)."""
        new_topology, result, pair = self._outcome(
            self.z, self.t, self.steps, self.observer, inputs
        )
        self.topology = (
            new_topology
            if mask is None or mask.all()
            else _where_batch(mask, new_topology, self.topology)
        )
        self._pair_of = (result.z, pair)
        return result

    def _outcome(self, z, t, steps, observer: ObserverState, inputs: tuple) -> tuple:
        """The topology update at states ``z`` (B, N, 6) and time ``t`` (B,) [s], and what they
        measure: ``(topology, StepResult, pair distances)``; ``inputs``: ``(u_n, u_d, u, d)``."""
        cfg = self.scenario
        u_n, u_d, u, d = inputs
        new_topology, out = topology.update_topology(
            self.topology,
            z[..., :3],
            z[..., 3:],
            t,
            cfg.avoidance,
            self.schedule,
            self.base_adjacency,
            self.obstacles,
            self.route_start,
        )
        pair, separation, obstacle_distance, cost, collision, estimate = measure_state(
            cfg, z, observer, u_n, out, self.offsets, self.obstacles
        )
        result = StepResult(
            z=copy_array(z),
            u_n=u_n,
            u_d=u_d,
            u_applied=u,
            disturbance=d,
            estimate=estimate,
            adjacency=out.adjacency,
            groups=out.groups,
            reference_velocity=out.reference_velocity,
            avoiding=out.avoiding,
            cost=cost,
            t=copy_array(t),
            step=copy_array(steps),
            truncated=steps >= self._n_steps,
            min_separation=separation,
            obstacle_distance=obstacle_distance,
            collision=collision,
            activated=out.activated,
            restored=out.restored,
            route_correction=out.route_correction,
        )
        return new_topology, result, pair

    # ------------------------------------------------------------------ copies
    def adopt(self, mask: np.ndarray, source: FormationSim) -> StepResult:
        """Take over the whole state of the ``mask`` copies from ``source`` (same scenario and
        batch size): positions, observer, topology, time, noise, random streams.

        Used to start episodes part-way along the mission: a copy is flown there in a second
        simulator and adopted. Copy b of ``source`` becomes copy b here.

        Returns:
            The :class:`StepResult` of every copy after the adoption.
        """
        mask = _host(mask, bool)
        if (
            source.backend != self.backend
            or source.batch_size != self.batch_size
            or source.n_uav != self.n_uav
            or source.scenario != self.scenario
        ):
            raise ValueError(
                "adopt needs a source simulator of the same scenario, N, B and backend"
            )
        if source.last is None or (self.last is None and not mask.all()):
            raise RuntimeError(
                "adopt() needs a source that has been reset, and a reset target unless every "
                "copy is adopted"
            )
        if source.noise_source != self.noise_source:
            raise ValueError("adopt needs a source simulator of the same noise source")
        for name in ("noise", "noise_pos"):  # on the host
            getattr(self, name)[mask] = getattr(source, name)[mask]
        on = self._put(mask)
        for name in ("z", "gust", "t", "steps", "route_start", "noise_keys"):
            getattr(self, name)[on] = getattr(source, name)[on]
        self.offsets[on] = source.offsets[on]
        self.base_adjacency[on] = source.base_adjacency[on]
        self.obstacles.take(on, source.obstacles)
        if isinstance(self.schedule, CopySchedules):
            assert isinstance(source.schedule, CopySchedules)
            self.schedule.times[on] = source.schedule.times[on]
            self.schedule.velocities[on] = source.schedule.velocities[on]
        ours, theirs = self.copy_disturbance, source.copy_disturbance
        for name in ("amplitude", "wind", "gust_std"):
            getattr(ours, name)[on] = getattr(theirs, name)[on]
        self.observer = _where_batch(on, source.observer, self.observer)
        self.topology = _where_batch(on, source.topology, self.topology)
        for b in np.flatnonzero(mask):
            # copies, not the objects: the source may go on drawing from its own
            self._rngs[b] = copy.deepcopy(source._rngs[b])
            self._seed_streams[b] = copy.deepcopy(source._seed_streams[b])
            self.scenes[b] = source.scenes[b]
            self._written[b] = source._written[b]
        self._noise_left = NOISE_BLOCK - int(self.noise_pos.max())
        self.last = source.last if self.last is None else _where_batch(on, source.last, self.last)
        return self.last

    def generator(self, copy: int) -> np.random.Generator:
        """The random generator of one copy (seeded at its last reset)."""
        return self._rngs[copy]

    # ------------------------------------------------------------------ queries
    @property
    def field(self) -> ObstacleField:
        """Every copy's obstacles (B, O, ...): the arrays the step reads."""
        return self.obstacles

    @property
    def obstacle_centers(self):
        """(B, O, 2) obstacle centres of each copy [m] (padding far away)."""
        return self.obstacles.centres

    @property
    def obstacle_radii(self):
        """(B, O) obstacle radii of each copy [m]."""
        return self.obstacles.radii

    def distances(
        self, pair: np.ndarray | SensedPairs | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nearest-UAV distance and nearest obstacle-surface distance, each (B, N) [m].

        The obstacle distance is +inf without obstacles and negative inside an obstacle; the
        UAV distance is +inf where no other UAV is within ``observation.sensing_radius``.

        Args:
            pair: (B, N, N) :func:`~uav_formation_env.core.cost.stage.pair_distances` of the
                current positions, or their :class:`SensedPairs`, if already computed.
        """
        if pair is None:
            pair = uav_pairs(self.z[..., :3], self.scenario.observation.sensing_radius)
        return measured_distances(self.scenario, self.z, pair, self.obstacles)

    def pair_distances_of(self, result: StepResult) -> np.ndarray | SensedPairs:
        """The UAV-UAV distances of ``result.z``: (B, N, N) [m] (+inf on the diagonal), or the
        :class:`SensedPairs` within ``observation.sensing_radius``. The ones this step computed
        for the separation term when ``result`` is the step's own result (one pass per step
        instead of two), else computed now."""
        z, pair = self._pair_of
        if z is result.z:
            return pair
        return uav_pairs(result.z[..., :3], self.scenario.observation.sensing_radius)

    def reference_preview(self) -> np.ndarray:
        """v^d over the MPC horizon, (B, N, H+1, 3) [m/s] (avoidance references held).

        The route return and the corner blend of now are held over the horizon on top of the
        schedule, as a policy sees them in its observation (the blend's ramp is not previewed).
        """
        assert self.last is not None, "call reset() first"
        blend = blend_offset(self.schedule, self.t, self.scenario.avoidance.turn_blend)
        return topology.reference_preview(
            self.schedule,
            self.t,
            self.dt,
            self.scenario.cost.horizon,
            self.last.reference_velocity,
            self.last.avoiding,
            self.last.route_correction + blend,
        )

    @property
    def observer_state(self) -> ObserverState:
        return self.observer
