"""Tests of the local (N-independent) observation: hand values per slot, slot selection against a
loop reference, padding obstacles, decoding, and the cross-check with core.observation at N = 5."""

from __future__ import annotations

import math
import timeit

import gymnasium
import numpy as np
import pytest

from uav_formation_env.config import PAPER_ADJACENCY, PAPER_OFFSETS
from uav_formation_env.core.local_observation import (
    LocalObservations,
    build_local_observations,
    decode_local_observations,
    local_observation_bounds,
    local_observation_dim,
)
from uav_formation_env.core.observation import build_observations, decode_observations

F32 = {"rtol": 2e-6, "atol": 2e-6}  # float32 output of O(1) values


def inputs(z, adjacency, offsets=None, centres=None, radii=None, present=None, **extra):
    """Keyword arguments of build_local_observations for states z (B, N, 6), the rest zero-ish."""
    z = np.asarray(z, dtype=float)
    batch, n_uav = z.shape[:2]
    if centres is None:
        centres, radii, present = np.zeros((batch, 0, 2)), np.zeros((batch, 0)), None
    if present is None:
        present = np.ones(np.shape(radii), dtype=bool)
    kwargs = {
        "z": z,
        "reference_velocity": z[..., 3:].copy(),
        "estimate": np.zeros((batch, n_uav, 3)),
        "adjacency": np.broadcast_to(np.asarray(adjacency, float), (batch, n_uav, n_uav)).copy(),
        "avoiding": np.zeros((batch, n_uav), dtype=bool),
        "time_fraction": np.zeros(batch),
        "offsets": np.zeros((n_uav, 6)) if offsets is None else np.asarray(offsets, dtype=float),
        "obstacle_centers": np.asarray(centres, dtype=float),
        "obstacle_radii": np.asarray(radii, dtype=float),
        "obstacle_present": np.asarray(present, dtype=bool),
        "min_separation": np.full((batch, n_uav), 10.0),
        # the neighbour-slot tests: proximity slots have their own tests (test_proximity_*)
        "nearest": 0,
    }
    kwargs.update(extra)
    return kwargs


def decode(obs, k=4, m=2):
    """decode_local_observations of observations built by ``inputs`` (no proximity slots)."""
    return decode_local_observations(obs, k, m, 0)


def random_inputs(rng, batch, n_uav, n_obs=3, grid=False):
    """Random inputs; ``grid``: integer positions, so that many distances tie exactly."""
    if grid:
        z = np.concatenate(
            (rng.integers(-3, 4, (batch, n_uav, 3)) * 10.0, rng.normal(size=(batch, n_uav, 3))), -1
        )
        centres = rng.integers(-5, 6, (batch, n_obs, 2)) * 10.0
        radii = rng.integers(0, 3, (batch, n_obs)) * 5.0
    else:
        z = rng.normal(size=(batch, n_uav, 6)) * [40, 40, 10, 5, 5, 1]
        centres = rng.normal(size=(batch, n_obs, 2)) * 80
        radii = rng.uniform(1, 20, (batch, n_obs))
    return inputs(
        z,
        rng.random((batch, n_uav, n_uav)) < 0.4,
        offsets=rng.normal(size=(n_uav, 6)) * [20, 20, 5, 1, 1, 0.2],
        centres=centres,
        radii=radii,
        present=rng.random((batch, n_obs)) < 0.7,
        reference_velocity=rng.normal(size=(batch, n_uav, 3)) * 5,
        estimate=rng.normal(size=(batch, n_uav, 3)) * 0.2,
        avoiding=rng.random((batch, n_uav)) < 0.5,
        time_fraction=rng.random(batch),
        min_separation=rng.uniform(0, 200, (batch, n_uav)),
        next_velocity=rng.normal(size=(batch, 3)) * 5,
        time_to_switch=rng.uniform(0, 400, batch),
    )


# ------------------------------------------------------------------------------------------------
# Layout
# ------------------------------------------------------------------------------------------------
def test_dim_and_bounds():
    assert local_observation_dim(4, 2) == 95  # default r = 2 proximity slots
    assert local_observation_dim(4, 2, 0) == 73
    assert local_observation_dim(0, 0, 0) == 19
    assert local_observation_dim(1, 3, 1) == 19 + 22 + 15
    low, high = local_observation_bounds(4, 2, 0)
    assert low.shape == high.shape == (73,) and low.dtype == np.float32
    assert np.all(low < high)
    assert (low[14], high[14], low[18], high[18]) == (-10, 10, 0, 10)
    np.testing.assert_array_equal(low[19:30], [0, 0, -10, -10, -10] + [-100] * 6)
    np.testing.assert_array_equal(high[63:68], [1, 10, 10, 100, 10])
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError):
            local_observation_dim(bad, 2)


@pytest.mark.parametrize("n_uav", [1, 3, 5, 20, 100])
def test_dim_independent_of_n(n_uav):
    out = build_local_observations(**random_inputs(np.random.default_rng(n_uav), 2, n_uav))
    assert isinstance(out, LocalObservations)
    assert out.obs.shape == (2, n_uav, 73) and out.obs.dtype == np.float32
    assert out.neighbour_index.shape == (2, n_uav, 4) and out.neighbour_index.dtype == np.int64
    low, high = local_observation_bounds(nearest=0)
    box = gymnasium.spaces.Box(low, high, dtype=np.float32)
    assert all(box.contains(row) for row in out.obs.reshape(-1, 73))


# ------------------------------------------------------------------------------------------------
# Hand-built cases
# ------------------------------------------------------------------------------------------------
def six_uav_case():
    """UAV 0 at the origin with in-neighbours {2, 4}; other UAVs 3 (10 m), 1 (30 m), 5 (50 m)."""
    p = [(0, 0, 0), (30, 0, 0), (0, 20, 0), (0, 0, 10), (40, 0, 0), (0, 50, 0)]
    v = [(10, 0, 0)] * 6
    v[2], v[4] = (12, 1, 0), (10, 0, -2)
    z = np.concatenate((p, v), axis=1)[None]
    adjacency = np.zeros((6, 6))
    adjacency[0, [2, 4]] = 1
    adjacency[1] = 1 - np.eye(6)[1]
    offsets = np.zeros((6, 6))
    offsets[2, :3] = (0, 15, 0)
    offsets[4] = (30, 0, 0, 1, 0, 0)
    reference = np.tile([8.0, 0.0, 0.0], (1, 6, 1))
    estimate = np.zeros((1, 6, 3))
    estimate[0, 0] = (0.1, -0.2, 0.05)
    # obstacle 1 is padding at UAV 0's own position: it would be the nearest if it counted
    centres, radii = [[(100, 0), (0, 0), (0, -40)]], [[10, 5, 20]]
    return inputs(
        z,
        adjacency,
        offsets=offsets,
        centres=centres,
        radii=radii,
        present=[[True, False, True]],
        reference_velocity=reference,
        estimate=estimate,
        avoiding=np.eye(6, dtype=bool)[:1],
        time_fraction=np.array([0.25]),
        next_velocity=np.array([[0.0, 10.0, 0.0]]),
        time_to_switch=np.array([25.0]),
    )


def test_six_uavs_every_slot_of_uav_0():
    out = build_local_observations(**six_uav_case())
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [2, 4, 3, 1])
    own = [0.5, 0, 0, 0.1, 0, 0, 0.4, 0, 0, 0.2, -0.4, 0.1, 0.25, 1, 0.1, 0, 0.5, 0, 0.5]
    neighbours = [
        [1, 1, 0, 0.2, 0, 0, 0.1, 0, 0.1, 0.05, 0],  # UAV 2: in-neighbour at 20 m
        [1, 1, 0.4, 0, 0, 0.2, 0, 0, -0.05, 0, -0.1],  # UAV 4: in-neighbour at 40 m
        [1, 0, 0, 0, 0.1, 0, 0, 0.2, 0, 0, 0],  # UAV 3: nearest other UAV, not a neighbour
        [1, 0, 0.3, 0, 0, 0.6, 0, 0, 0, 0, 0],  # UAV 1 (30 m); UAV 5 (50 m) has no slot
    ]
    obstacles = [[1, 0, -0.4, 0.2, 0.2], [1, 1, 0, 0.1, 0.9]]  # obstacles 2 then 0
    expected = np.concatenate([own, *neighbours, *obstacles])
    np.testing.assert_allclose(out.obs[0, 0], expected, **F32)


def test_proximity_slots_show_the_nearest_non_slot_uavs():
    # UAV 0 of the six-UAV case with k = 2: its in-neighbours 2 (20 m) and 4 (40 m) fill the
    # neighbour slots; the proximity slots hold UAV 3 (10 m, nearer than both) and UAV 1 (30 m)
    out = build_local_observations(**{**six_uav_case(), "nearest": 2}, k=2)
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [2, 4, 3, 1])
    decoded = decode_local_observations(out.obs, 2, 2, 2)
    np.testing.assert_array_equal(decoded.neighbour[0, 0], [True, True, False, False])
    np.testing.assert_allclose(decoded.relative_position[0, 0, 2], [0, 0, 10], **F32)
    np.testing.assert_allclose(decoded.relative_position[0, 0, 3], [30, 0, 0], **F32)
    # UAV 1 receives from all five: neighbour slots 4 (10 m) and 0 (30 m), then by distance
    # alone 3 (31.6 m) and 2 (36.1 m), flagged as in-neighbours
    np.testing.assert_array_equal(out.neighbour_index[0, 1], [4, 0, 3, 2])
    np.testing.assert_array_equal(decoded.neighbour[0, 1], [True] * 4)
    # more proximity slots than UAVs left: absent slots are -1 and all zeros
    wide = build_local_observations(**{**six_uav_case(), "nearest": 5}, k=2)
    np.testing.assert_array_equal(wide.neighbour_index[0, 0], [2, 4, 3, 1, 5, -1, -1])
    slots = wide.obs[0, 0, 19 : 19 + 11 * 7].reshape(7, 11)
    assert not slots[5:].any()
    assert wide.obs.shape[-1] == local_observation_dim(2, 2, 5)


def test_six_uavs_other_receivers():
    out = build_local_observations(**six_uav_case())
    # UAV 1 receives from all: the 4 nearest of its 5 in-neighbours, all flagged 1
    # (distances from (30, 0, 0): UAV 4 10, UAV 0 30, UAV 3 31.6, UAV 2 36.1, UAV 5 58.3)
    np.testing.assert_array_equal(out.neighbour_index[0, 1], [4, 0, 3, 2])
    decoded = decode(out.obs)
    np.testing.assert_array_equal(decoded.neighbour[0, 1], [True] * 4)
    # UAV 3 has no in-neighbour: the 4 nearest other UAVs, flagged 0, ties to the lowest index
    # (from (0, 0, 10): UAV 0 10, UAV 2 22.4, UAV 1 31.6, UAV 4 41.2, UAV 5 51.0)
    np.testing.assert_array_equal(out.neighbour_index[0, 3], [0, 2, 1, 4])
    np.testing.assert_array_equal(decoded.neighbour[0, 3], [False] * 4)


def test_three_uavs_absent_slots_are_zero():
    z = np.zeros((1, 3, 6))
    z[0, 1, :3], z[0, 2, :3] = (0, 10, 0), (5, 0, 0)
    adjacency = [[0, 1, 0], [1, 0, 1], [0, 0, 0]]
    out = build_local_observations(**inputs(z, adjacency))
    np.testing.assert_array_equal(
        out.neighbour_index[0], [[1, 2, -1, -1], [0, 2, -1, -1], [0, 1, -1, -1]]
    )
    slots = out.obs[0, :, 19:63].reshape(3, 4, 11)
    np.testing.assert_array_equal(slots[:, 2:], 0.0)
    np.testing.assert_allclose(slots[0, 0, :5], [1, 1, 0, 0.1, 0], **F32)
    np.testing.assert_allclose(slots[0, 1, :5], [1, 0, 0.05, 0, 0], **F32)
    np.testing.assert_allclose(slots[2, :2, :2], [[1, 0], [1, 0]])
    np.testing.assert_array_equal(out.obs[0, :, 63:], 0.0)  # no obstacles at all


def test_more_than_k_neighbours_keeps_the_k_nearest():
    n_uav = 7
    z = np.zeros((1, n_uav, 6))
    z[0, 1:, 0] = [60, 10, 50, 20, 40, 30]  # UAVs 1..6 on a line, at these distances from 0
    out = build_local_observations(**inputs(z, 1 - np.eye(n_uav)), k=4)
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [2, 4, 6, 5])
    np.testing.assert_array_equal(decode(out.obs).neighbour[0, 0], True)
    k2 = build_local_observations(**inputs(z, 1 - np.eye(n_uav)), k=2, m=0)
    assert k2.obs.shape == (1, n_uav, 19 + 22)
    np.testing.assert_array_equal(k2.neighbour_index[0, 0], [2, 4])


def test_paper_formation_ties_break_by_index():
    # at the exact V shape, UAV 0 sees 1 and 2 at sqrt(500) m, 3 and 4 at sqrt(2000) m
    z = np.asarray(PAPER_OFFSETS)[None]
    out = build_local_observations(**inputs(z, PAPER_ADJACENCY, offsets=PAPER_OFFSETS))
    # in-neighbours {1, 3, 4} nearest first (3 before 4: a tie), then the non-neighbour 2
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [1, 3, 4, 2])
    np.testing.assert_array_equal(out.obs[0, 0, [20, 31, 42, 53]], [1, 1, 1, 0])
    # every slot at the exact shape: zero formation error
    slots = out.obs[0, :, 19:63].reshape(5, 4, 11)
    np.testing.assert_array_equal(slots[..., 5:], 0.0)


def test_ties_at_the_kth_slot_take_the_lowest_index():
    # 9 UAVs exactly 5 m from UAV 0 (integer coordinates: exact distances), one a neighbour
    ring = [(3, 4, 0), (4, 3, 0), (5, 0, 0), (0, 5, 0), (-3, 4, 0), (-4, -3, 0), (0, 0, 5)]
    ring += [(0, -5, 0), (-5, 0, 0)]
    z = np.zeros((1, 10, 6))
    z[0, 1:, :3] = ring
    adjacency = np.zeros((10, 10))
    adjacency[0, 8] = 1
    out = build_local_observations(**inputs(z, adjacency))
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [8, 1, 2, 3])
    out = build_local_observations(**inputs(z, np.zeros((10, 10))), k=6)
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [1, 2, 3, 4, 5, 6])


def test_distances_are_ranked_exactly():
    # UAV 2 is one ulp nearer than UAV 1 at ~1000 m; neither is a neighbour. A float key
    # d + large would round both to the same value and put UAV 1 first.
    z = np.zeros((1, 4, 6))
    z[0, 1, 0] = np.nextafter(1000.0, np.inf)
    z[0, 2, 0] = 1000.0
    z[0, 3, 0] = -5.0
    adjacency = np.zeros((4, 4))
    adjacency[0, 3] = 1
    out = build_local_observations(**inputs(z, adjacency), k=2)
    np.testing.assert_array_equal(out.neighbour_index[0, 0], [3, 2])


# ------------------------------------------------------------------------------------------------
# Selection against a loop reference
# ------------------------------------------------------------------------------------------------
def reference_slots(kwargs, k, m, nearest=0):
    """Per (b, i): the neighbour then proximity slots' UAVs and the obstacle slots' obstacles, by
    Python loops."""
    z, adjacency = kwargs["z"], kwargs["adjacency"]
    batch, n_uav = z.shape[:2]
    neighbours = np.full((batch, n_uav, k + nearest), -1)
    obstacles = np.full((batch, n_uav, m), -1)
    for b in range(batch):
        for i in range(n_uav):
            dist = {j: math.dist(z[b, i, :3], z[b, j, :3]) for j in range(n_uav) if j != i}
            order = sorted(dist, key=lambda j: (adjacency[b, i, j] == 0, dist[j], j))[:k]
            rest = sorted((j for j in dist if j not in order), key=lambda j: (dist[j], j))
            neighbours[b, i, : len(order)] = order
            near = rest[:nearest]
            neighbours[b, i, k : k + len(near)] = near
            surface = {
                o: math.dist(z[b, i, :2], kwargs["obstacle_centers"][b, o])
                - kwargs["obstacle_radii"][b, o]
                for o in range(len(kwargs["obstacle_radii"][b]))
                if kwargs["obstacle_present"][b, o]
            }
            order = sorted(surface, key=lambda o: (surface[o], o))[:m]
            obstacles[b, i, : len(order)] = order
    return neighbours, obstacles


@pytest.mark.parametrize("seed", range(12))
def test_selection_matches_loop_reference(seed):
    rng = np.random.default_rng(seed)
    n_uav, n_obs = int(rng.integers(1, 14)), int(rng.integers(0, 6))
    k, m, r = int(rng.integers(0, 7)), int(rng.integers(0, 4)), int(rng.integers(0, 3))
    kwargs = random_inputs(rng, 3, n_uav, n_obs, grid=seed % 2 == 0)  # even seeds: many ties
    kwargs["nearest"] = r
    out = build_local_observations(**kwargs, k=k, m=m)
    neighbours, obstacles = reference_slots(kwargs, k, m, r)
    np.testing.assert_array_equal(out.neighbour_index, neighbours)
    decoded = decode_local_observations(out.obs, k, m, r)
    np.testing.assert_array_equal(decoded.slot_present, neighbours >= 0)
    np.testing.assert_array_equal(decoded.obstacle_present, obstacles >= 0)
    z, offsets = kwargs["z"], kwargs["offsets"]
    b, i = np.indices(neighbours.shape)[:2]
    j = np.maximum(neighbours, 0)
    present = (neighbours >= 0)[..., None]
    rel_p = np.where(present, z[b, j, :3] - z[b, i, :3], 0.0)
    a = z - offsets
    rel_a = np.where(present, a[b, j] - a[b, i], 0.0)
    flag = (kwargs["adjacency"][b, i, j] != 0) & (neighbours >= 0)
    np.testing.assert_array_equal(decoded.neighbour, flag)
    np.testing.assert_allclose(decoded.relative_position, np.clip(rel_p, -1000, 1000), atol=1e-4)
    np.testing.assert_allclose(decoded.relative_formation_error, rel_a, rtol=1e-6, atol=1e-4)


# ------------------------------------------------------------------------------------------------
# Obstacles
# ------------------------------------------------------------------------------------------------
def test_obstacles_nearest_first_padding_masked_whatever_its_values():
    z = np.zeros((2, 2, 6))
    z[:, 1, :3] = (50, 0, 0)
    centres = np.array(
        [
            [(1e12, 1e12), (0, 30), (np.nan, np.inf), (0, -60), (5, 0)],
            [(1e12, -1e12), (0, 0), (0, 0), (0, 0), (0, 0)],
        ]
    )
    radii = np.array([[1e12, 10, 3, 10, np.inf], [1.0, 1, 1, 1, 1]])
    present = np.array([[False, True, False, True, False], [False] * 5])
    kwargs = inputs(z, np.zeros((2, 2)), centres=centres, radii=radii, present=present)
    with np.errstate(all="raise"):  # padding never enters the arithmetic
        out = build_local_observations(**kwargs, m=3)
    decoded = decode(out.obs, 4, 3)
    # copy 0, UAV 0: obstacle 1 (surface 20 m), then obstacle 3 (50 m); 2 present -> slot 2 absent
    np.testing.assert_array_equal(decoded.obstacle_present[0, 0], [True, True, False])
    np.testing.assert_allclose(decoded.obstacle_relative[0, 0], [(0, 30), (0, -60), (0, 0)])
    np.testing.assert_allclose(decoded.obstacle_radius[0, 0], [10, 10, 0])
    np.testing.assert_allclose(decoded.obstacle_surface[0, 0], [20, 50, 0], rtol=1e-6)
    # UAV 1 at (50, 0): obstacle 1 at sqrt(3400) - 10 = 48.3 m, obstacle 3 at 68.1 m
    np.testing.assert_allclose(
        decoded.obstacle_surface[0, 1], [math.sqrt(3400) - 10, math.sqrt(6100) - 10, 0], rtol=1e-6
    )
    # copy 1 has only padding: all obstacle slots zero
    np.testing.assert_array_equal(out.obs[1, :, 63:], 0.0)


def test_obstacle_far_away_is_clipped():
    z = np.zeros((1, 2, 6))
    z[0, 1, 0] = 5000.0  # also far from UAV 0: relative position clipped at ±10 (1000 m)
    kwargs = inputs(z, np.zeros((2, 2)), centres=[[(3000, -4000)]], radii=[[50.0]])
    out = build_local_observations(**kwargs, m=1)
    np.testing.assert_allclose(out.obs[0, 0, 63:68], [1, 10, -10, 0.5, 10])
    np.testing.assert_allclose(out.obs[0, 0, 21:24], [10, 0, 0])


# ------------------------------------------------------------------------------------------------
# Own features, decoding
# ------------------------------------------------------------------------------------------------
def test_next_leg_defaults_and_clipping():
    kwargs = random_inputs(np.random.default_rng(3), 2, 4)
    del kwargs["next_velocity"], kwargs["time_to_switch"]
    out = build_local_observations(**kwargs)
    decoded = decode(out.obs)
    np.testing.assert_allclose(decoded.next_velocity, kwargs["reference_velocity"], rtol=1e-6)
    np.testing.assert_array_equal(decoded.time_to_switch, 0.0)
    kwargs["next_velocity"] = np.array([[1.0, 2.0, 3.0], [-4.0, 0.0, 0.5]])
    kwargs["time_to_switch"] = np.array([1e4, -3.0])  # clipped to [0, 500] s
    decoded = decode(build_local_observations(**kwargs).obs)
    np.testing.assert_allclose(
        decoded.next_velocity, np.repeat(kwargs["next_velocity"][:, None], 4, 1), rtol=1e-6
    )
    np.testing.assert_allclose(decoded.time_to_switch, [[500.0] * 4, [0.0] * 4])


def test_decode_inverts_build():
    kwargs = random_inputs(np.random.default_rng(7), 3, 9, n_obs=4)
    out = build_local_observations(**kwargs)
    d = decode(out.obs)
    z = kwargs["z"]
    tol = {"rtol": 1e-6, "atol": 1e-5}
    np.testing.assert_allclose(d.velocity, z[..., 3:], **tol)
    np.testing.assert_allclose(d.velocity_error, z[..., 3:] - kwargs["reference_velocity"], **tol)
    np.testing.assert_allclose(d.reference_velocity, kwargs["reference_velocity"], **tol)
    np.testing.assert_allclose(d.estimate, kwargs["estimate"], **tol)
    np.testing.assert_allclose(d.time_fraction, np.repeat(kwargs["time_fraction"][:, None], 9, 1))
    np.testing.assert_array_equal(d.avoiding, kwargs["avoiding"])
    np.testing.assert_allclose(d.nearest_distance, kwargs["min_separation"], rtol=1e-6)
    np.testing.assert_allclose(
        d.time_to_switch, np.repeat(kwargs["time_to_switch"][:, None], 9, 1), rtol=1e-6
    )
    j = np.maximum(out.neighbour_index, 0)
    b, i = np.indices(j.shape)[:2]
    present = (out.neighbour_index >= 0)[..., None]
    np.testing.assert_allclose(
        d.relative_position, np.where(present, z[b, j, :3] - z[b, i, :3], 0), **tol
    )
    # re-encoding the decoded vector gives the same float32 numbers
    again = np.concatenate(
        (
            d.velocity / 20,
            d.velocity_error / 20,
            d.reference_velocity / 20,
            d.estimate / 0.5,
            d.time_fraction[..., None],
            d.avoiding[..., None],
            d.nearest_distance[..., None] / 100,
            d.next_velocity / 20,
            d.time_to_switch[..., None] / 50,
            np.concatenate(
                (
                    d.slot_present[..., None],
                    d.neighbour[..., None],
                    d.relative_position / 100,
                    d.relative_formation_error / [50, 50, 50, 20, 20, 20],
                ),
                axis=-1,
            ).reshape(3, 9, 44),
            np.concatenate(
                (
                    d.obstacle_present[..., None],
                    d.obstacle_relative / 100,
                    d.obstacle_radius[..., None] / 100,
                    d.obstacle_surface[..., None] / 100,
                ),
                axis=-1,
            ).reshape(3, 9, 10),
        ),
        axis=-1,
    )
    np.testing.assert_allclose(again, out.obs, rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="last axis"):
        decode(out.obs, k=3)


# ------------------------------------------------------------------------------------------------
# Consistency with core.observation at N = 5, batches
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mirrored", [False, True])
def test_paper_graph_matches_full_observation(mirrored):
    rng = np.random.default_rng(11)
    batch = 4
    offsets = np.asarray(PAPER_OFFSETS) * (-1.0 if mirrored else 1.0)  # the literal reading
    z = offsets[None] + rng.normal(size=(batch, 5, 6)) * [8, 8, 2, 1, 1, 0.3]
    kwargs = inputs(z, PAPER_ADJACENCY, offsets=offsets)
    kwargs["estimate"] = rng.normal(size=(batch, 5, 3)) * 0.2
    local = build_local_observations(**kwargs)
    full = build_observations(
        z,
        kwargs["reference_velocity"],
        kwargs["estimate"],
        kwargs["adjacency"],
        kwargs["avoiding"],
        kwargs["time_fraction"],
        offsets,
        np.zeros((0, 2)),
        np.zeros(0),
        kwargs["min_separation"],
    )
    ours, theirs = decode(local.obs), decode_observations(full, 5)
    np.testing.assert_allclose(ours.velocity, theirs.velocity, rtol=1e-6)
    np.testing.assert_allclose(ours.estimate, theirs.estimate, rtol=1e-6)
    adjacency = np.asarray(PAPER_ADJACENCY)
    for b in range(batch):
        for i in range(5):
            index = local.neighbour_index[b, i]
            # k = 4 = N - 1: every other UAV has a slot, each in-neighbour flagged 1
            assert sorted(index) == [j for j in range(5) if j != i]
            np.testing.assert_array_equal(ours.neighbour[b, i], adjacency[i, index] == 1)
            column = index - (index > i)  # position of j among i's others in core.observation
            np.testing.assert_array_equal(ours.neighbour[b, i], theirs.neighbour[b, i, column])
            np.testing.assert_allclose(
                ours.relative_formation_error[b, i],
                theirs.relative_formation_error[b, i, column],
                rtol=1e-6,
                atol=1e-5,
            )


def test_batch_copies_are_independent():
    rng = np.random.default_rng(5)
    kwargs = random_inputs(rng, 5, 8, n_obs=4, grid=True)
    kwargs["offsets"] = rng.normal(size=(5, 8, 6)) * 20  # one formation per copy
    del kwargs["nearest"]  # with the default proximity slots
    batch = build_local_observations(**kwargs, k=2)
    assert (batch.neighbour_index[..., 2:] >= 0).all()  # the proximity slots are in use
    for b in range(5):
        alone = {key: value[b : b + 1] for key, value in kwargs.items()}
        alone["offsets"] = kwargs["offsets"][b]  # (N, 6), shared by a batch of one
        single = build_local_observations(**alone, k=2)
        np.testing.assert_array_equal(single.obs[0], batch.obs[b])
        np.testing.assert_array_equal(single.neighbour_index[0], batch.neighbour_index[b])


def test_large_batch_builds_quickly():
    kwargs = random_inputs(np.random.default_rng(0), 256, 100, n_obs=8)
    seconds = min(timeit.repeat(lambda: build_local_observations(**kwargs), number=1, repeat=2))
    out = build_local_observations(**kwargs)
    assert out.obs.shape == (256, 100, 73) and np.isfinite(out.obs).all()
    print(f"B=256, N=100: {seconds * 1e3:.0f} ms")
    assert seconds < 10.0  # a sanity bound only (~0.2 s on a shared 2-core machine)
