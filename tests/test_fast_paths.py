"""The small-batch fast paths: cached constants are read-only, shortcuts equal the general path.

Each shortcut is taken only when its result is provably the general path's, bit for bit; these
tests force or bypass the shortcut and compare with ``np.array_equal``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env import parallel_env
from uav_formation_env.config import (
    AvoidanceConfig,
    CostConfig,
    ObstacleConfig,
    ScheduleConfig,
)
from uav_formation_env.core import topology
from uav_formation_env.core.cost import others_mask, separation_sq, stage_cost
from uav_formation_env.core.cost.stage import pair_distances
from uav_formation_env.core.disturbances import paper_sinusoid
from uav_formation_env.core.observation import others_index
from uav_formation_env.core.obstacles import detection_sq, obstacle_arrays
from uav_formation_env.core.reference import config_cache, schedule_arrays
from uav_formation_env.episode import validate_actions

N = 5


def _state(rng: np.random.Generator, batch: int, spread: float) -> np.ndarray:
    z = rng.normal(size=(batch, N, 6))
    z[..., :3] *= spread
    z[..., 3:] *= 5.0
    return z


# ------------------------------------------------------------------------------------------------
# cached constants
# ------------------------------------------------------------------------------------------------


def test_cached_arrays_are_shared_and_read_only() -> None:
    avoidance, schedule = AvoidanceConfig(), ScheduleConfig()
    cached = [
        *obstacle_arrays(avoidance),
        *schedule_arrays(schedule),
        others_index(N),
        detection_sq(avoidance),
    ]
    for array in cached:
        assert not array.flags.writeable
        with pytest.raises(ValueError):
            array[...] = 0
    assert obstacle_arrays(avoidance)[0] is obstacle_arrays(avoidance)[0]
    assert others_index(N) is others_index(N)


def test_config_cache_keys_by_identity_then_by_value() -> None:
    calls = []

    @config_cache
    def radii(avoidance: AvoidanceConfig) -> tuple[float, ...]:
        calls.append(avoidance)
        return tuple(ob.radius for ob in avoidance.obstacles)

    first = AvoidanceConfig()
    twin = dataclasses.replace(first)  # equal, not identical
    other = AvoidanceConfig(obstacles=(ObstacleConfig((0.0, 0.0), 12.0),))
    assert radii(first) == radii(first) == radii(twin) == (30.0, 30.0)
    assert radii(other) == (12.0,)
    assert len(calls) == 2  # one computation per distinct value


def test_cached_results_do_not_leak_mutation() -> None:
    """Results built from cached constants are fresh arrays the caller may modify."""
    velocity = topology.preset_velocity(ScheduleConfig(), 150.0)
    velocity[0] = 99.0
    assert topology.preset_velocity(ScheduleConfig(), 150.0)[0] == -20.0
    wave = paper_sinusoid(np.array([1.0, 2.0]), N, 0.2, 40.0)
    wave[...] = 0.0
    assert np.any(paper_sinusoid(np.array([1.0, 2.0]), N, 0.2, 40.0) != 0.0)


# ------------------------------------------------------------------------------------------------
# stage cost: separation shortcut and the shared pair distances
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("spread", [0.5, 4.0, 300.0])  # crowded, some close pairs, all apart
def test_stage_separation_equals_separation_sq(spread: float) -> None:
    rng = np.random.default_rng(1)
    batch = 7
    z = _state(rng, batch, spread)
    u = rng.normal(size=(batch, N, 3))
    reference = rng.normal(size=(batch, N, 3))
    adjacency = (rng.random((batch, N, N)) < 0.6) * (1.0 - np.eye(N))
    offsets = rng.normal(size=(N, 6))
    weights = CostConfig(separation=30.0, separation_distance=10.0)
    positions = z[..., :3]
    general = weights.separation * separation_sq(
        positions,
        np.broadcast_to(positions[:, None], (batch, N, N, 3)),
        others_mask(batch, N),
        weights.separation_distance,
    )
    terms = stage_cost(z, u, reference, adjacency, offsets, weights)
    assert np.array_equal(terms.separation, general)
    shared = stage_cost(
        z, u, reference, adjacency, offsets, weights, pair_distance=pair_distances(positions)
    )
    for name, value in terms.as_dict().items():
        assert np.array_equal(getattr(shared, name), value), name


def test_pair_distances_diagonal_and_values() -> None:
    rng = np.random.default_rng(2)
    positions = rng.normal(size=(3, N, 3)) * 50.0
    pair = pair_distances(positions)
    assert np.all(np.isinf(pair[:, np.arange(N), np.arange(N)]))
    off = ~np.eye(N, dtype=bool)
    diff = positions[:, :, None] - positions[:, None]
    expected = np.sqrt(np.einsum("bijk,bijk->bij", diff, diff))
    assert np.array_equal(pair[:, off], expected[:, off])


# ------------------------------------------------------------------------------------------------
# topology: the fast exit equals the general path
# ------------------------------------------------------------------------------------------------


def test_topology_fast_exit_equals_general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Force the general path (every idle obstacle counts as near) and compare outputs."""
    rng = np.random.default_rng(3)
    avoidance = AvoidanceConfig()
    schedule = ScheduleConfig()
    h0 = np.ones((N, N)) - np.eye(N)
    batch = 6
    # every copy outside all detection circles (the fast exit), some just outside, with a mix
    # of idle and done obstacles and times on both sides of a preset switch
    centres = np.array([ob.center for ob in avoidance.obstacles])
    anchor = centres[rng.integers(0, len(centres), batch)]
    angle = rng.uniform(0.0, 2.0 * np.pi, (batch, 1))
    radius = avoidance.obstacles[0].radius + avoidance.detection_margin + 1.0
    xy = anchor[:, None] + (radius + rng.uniform(0.0, 50.0, (batch, N))[..., None]) * np.stack(
        [np.cos(angle), np.sin(angle)], axis=-1
    )
    positions = np.concatenate([xy, rng.normal(size=(batch, N, 1))], axis=-1)
    velocities = rng.normal(size=(batch, N, 3))
    state = topology.init_topology(batch, N, len(centres))
    state.status[::2, 0] = topology.DONE
    t = np.linspace(40.0, 60.0, batch)

    def update() -> tuple[topology.TopologyState, topology.TopologyOutput]:
        return topology.update_topology(state, positions, velocities, t, avoidance, schedule, h0)

    fast_state, fast_out = update()
    monkeypatch.setattr(topology, "detection_sq", lambda cfg: np.full(len(cfg.obstacles), np.inf))
    slow_state, slow_out = update()
    for name in topology.TopologyState.__dataclass_fields__:
        a, b = getattr(fast_state, name), getattr(slow_state, name)
        assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True), name
        assert not np.shares_memory(a, getattr(state, name)), name
    for name in topology.TopologyOutput.__dataclass_fields__:
        a, b = getattr(fast_out, name), getattr(slow_out, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert not fast_out.activated.any()


# ------------------------------------------------------------------------------------------------
# env: action validation fast path
# ------------------------------------------------------------------------------------------------


def test_validate_actions_fast_path_and_errors() -> None:
    agents = [f"uav_{i}" for i in range(3)]
    actions = {a: np.array([0.5, -2.0, 1.5], dtype=np.float32) for a in agents}
    clipped = validate_actions(actions, agents)
    assert clipped.dtype == np.float64 and clipped.shape == (3, 3)
    assert np.array_equal(clipped, np.tile([0.5, -1.0, 1.0], (3, 1)))
    bad = {
        "uav_1": {**actions, "uav_1": np.array([np.nan, 0.0, 0.0])},
        "uav_2": {**actions, "uav_2": np.zeros(4)},
        "missing": {a: actions[a] for a in agents[:2]},
        "unknown": {**{a: actions[a] for a in agents[:2]}, "uav_9": np.zeros(3)},
        "uav_0": {**actions, "uav_0": "fast"},
    }
    for word, value in bad.items():
        with pytest.raises(ValueError, match=word):
            validate_actions(value, agents)


def test_env_infos_do_not_alias_the_simulator() -> None:
    env = parallel_env("paper")
    env.reset(seed=0)
    actions = {a: np.zeros(3, dtype=np.float32) for a in env.agents}
    _, _, _, _, infos = env.step(actions)
    position = env.sim.z[0, 0, :3].copy()
    infos["uav_0"]["position"][:] = 1e9
    infos["uav_0"]["neighbours"][:] = True
    assert np.array_equal(env.sim.z[0, 0, :3], position)
    _, _, _, _, infos = env.step(actions)
    assert not infos["uav_0"]["neighbours"][0]  # a UAV never receives from itself
