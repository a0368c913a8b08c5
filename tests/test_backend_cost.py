"""The stage cost J_i (core/cost/stage.py) and the UAV pair distances (core/proximity.py) on both
backends.

numpy is the reference; torch (float64, on the CPU in CI, on CUDA when present) must give the
same numbers, with the separation term on, for random states, dense random and the paper's
graphs, shared and per-copy offsets, both offset readings, and the pair distances given as a
matrix or as the grid's :class:`SensedPairs` (which stays numpy-only: torch uses the matrix).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from uav_formation_env.config import CostConfig
from uav_formation_env.core import array_api
from uav_formation_env.core.cost import (
    NeighbourMoments,
    anchored,
    formation_error_sq,
    neighbour_moments,
    others_mask,
    separation_sq,
    stage_cost,
    take_flat,
    velocity_error_sq,
)
from uav_formation_env.core.proximity import (
    GRID_MIN_UAVS,
    SensedPairs,
    gap_sq,
    nearest_distance,
    pair_distances,
    sensed_pairs,
    uav_pairs,
)
from uav_formation_env.scenarios import make_scenario, swarm_scenario

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
TOL = dict(rtol=1e-12, atol=1e-12)
PAPER = make_scenario(5)  # the paper's 5 UAVs: leader chain graph, V offsets; s = 30, d_s = 10 m
NAMES = ("formation", "energy", "terminal", "velocity", "separation", "obstacle")


def on(x, device):
    """numpy -> torch float64 (or int/bool as it is) on ``device``."""
    return torch.as_tensor(np.array(x), device=device)  # a copy: x may be read-only


def close(got, expected) -> None:
    assert isinstance(got, torch.Tensor)
    np.testing.assert_allclose(array_api.to_numpy(got), expected, **TOL)


def random_case(
    batch: int, n_uav: int, graph: str, per_copy: bool, seed: int, spread: float, near: bool = True
):
    """Random states within ``spread`` [m] of a far point; with ``near`` UAVs 0, 1 (and 2) closer
    than d_s = 10 m."""
    rng = np.random.default_rng(seed)
    z = np.concatenate(
        (
            rng.uniform(-spread, spread, (batch, n_uav, 3)) + [300.0, -80.0, 40.0],
            rng.normal(size=(batch, n_uav, 3)) * 5.0,
        ),
        axis=-1,
    )
    if near:
        z[:, 1, :3] = z[:, 0, :3] + [1.5, 2.0, 0.0]  # 2.5 m apart: the separation term is on
        z[:, 2:3, :3] = z[:, 0:1, :3]  # on top of each other (where N >= 3)
    u = rng.normal(size=(batch, n_uav, 3))
    ref = rng.normal(size=(batch, n_uav, 3)) * 4.0
    if graph == "paper":
        adj = np.broadcast_to(np.asarray(PAPER.formation.adjacency, float), (batch, 5, 5))
    elif graph == "dense":
        adj = (rng.uniform(size=(batch, n_uav, n_uav)) < 0.6).astype(float)
        adj[:, np.arange(n_uav), np.arange(n_uav)] = 0.0
    else:  # "none": nobody hears anybody
        adj = np.zeros((batch, n_uav, n_uav))
    shape = (batch, n_uav, 6) if per_copy else (n_uav, 6)
    offsets = rng.normal(size=shape) * 10.0
    if graph == "paper" and not per_copy:
        offsets = np.asarray(PAPER.formation.offsets, float)
    return z, u, ref, np.ascontiguousarray(adj), offsets


def assert_terms_equal(got, expected) -> None:
    assert set(got.as_dict()) == set(NAMES)
    for name in NAMES:
        close(got.as_dict()[name], getattr(expected, name))
    close(got.total, expected.total)


# ---------------------------------------------------------------------------------------------
# the shim functions added for these modules


def test_einsum_in_and_asarray_like():
    a, b = np.arange(6.0).reshape(2, 3), np.arange(12.0).reshape(3, 4)
    expected = np.einsum("ij,jk->ik", a, b)
    np.testing.assert_array_equal(array_api.einsum_in(np, "ij,jk->ik", a, b), expected)
    xp = array_api.namespace(torch.zeros(1))
    got = array_api.einsum_in(xp, "ij,jk->ik", torch.from_numpy(a), torch.from_numpy(b))
    np.testing.assert_array_equal(array_api.to_numpy(got), expected)
    # numpy `like`: the very same object back; torch `like`: its dtype and device, a copy of a
    # read-only numpy array without torch's warning, a matching tensor as it is
    read_only = np.broadcast_to(np.eye(3), (2, 3, 3))
    assert array_api.asarray_like(read_only, np.zeros(2)) is read_only
    like = torch.zeros(2, dtype=torch.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        converted = array_api.asarray_like(read_only, like)
    assert converted.dtype == torch.float32 and tuple(converted.shape) == (2, 3, 3)
    np.testing.assert_array_equal(converted.numpy(), read_only)
    assert array_api.asarray_like(like, like) is like
    # the one-array namespace and the einsum callable
    assert array_api.namespace_of(a) is np and array_api.namespace_of(1.0) is np
    assert array_api.namespace_of(like) is xp
    assert array_api.einsum_function(np) is np.einsum
    assert array_api.einsum_function(xp) is torch.einsum


# ---------------------------------------------------------------------------------------------
# stage_cost


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(
    "batch, n_uav, graph, per_copy",
    [
        (1, 5, "paper", False),
        (4, 5, "paper", False),
        (3, 5, "paper", True),
        (1, 2, "dense", False),
        (4, 7, "dense", True),
        (2, 12, "dense", False),
        (3, 6, "none", True),
    ],
)
def test_stage_cost_equal_on_torch(device, batch, n_uav, graph, per_copy):
    z, u, ref, adj, offsets = random_case(batch, n_uav, graph, per_copy, seed=n_uav, spread=20.0)
    weights = PAPER.cost
    expected = stage_cost(z, u, ref, adj, offsets, weights)
    assert expected.separation.max() > 0  # the separation term is on here
    t = {name: on(x, device) for name, x in dict(z=z, u=u, ref=ref, adj=adj, off=offsets).items()}
    got = stage_cost(t["z"], t["u"], t["ref"], t["adj"], t["off"], weights)
    assert_terms_equal(got, expected)
    assert got.formation.device.type == torch.device(device).type
    # the pair distances given as a matrix (and as the grid's pairs within R >= d_s)
    pairs = pair_distances(z[..., :3])
    got = stage_cost(t["z"], t["u"], t["ref"], t["adj"], t["off"], weights, on(pairs, device))
    assert_terms_equal(got, expected)
    grid = sensed_pairs(z[..., :3], 12.0)
    by_grid = stage_cost(z, u, ref, adj, offsets, weights, grid)
    got = stage_cost(t["z"], t["u"], t["ref"], t["adj"], t["off"], weights, grid)
    assert_terms_equal(got, by_grid)
    close(got.separation, expected.separation)
    # adjacency and offsets straight from the config as (read-only) numpy
    got = stage_cost(t["z"], t["u"], t["ref"], np.broadcast_to(adj, adj.shape), offsets, weights)
    assert_terms_equal(got, expected)


@pytest.mark.parametrize("device", DEVICES)
def test_stage_cost_separation_off_and_far_apart_is_exactly_zero(device):
    # far apart: numpy skips the term (+0); torch sums it and must get the same +0
    z, u, ref, adj, offsets = random_case(3, 6, "dense", False, seed=1, spread=1e4, near=False)
    assert pair_distances(z[..., :3]).min() > 10.0  # numpy takes its shortcut
    weights = PAPER.cost
    for w in (weights, CostConfig(q=1.0, r=5.0, n=10.0, separation=0.0)):
        expected = stage_cost(z, u, ref, adj, offsets, w)
        got = stage_cost(
            on(z, device), on(u, device), on(ref, device), on(adj, device), on(offsets, device), w
        )
        assert_terms_equal(got, expected)
        assert not got.separation.any() and not torch.signbit(got.separation).any()
        assert not got.terminal.any()


@pytest.mark.parametrize("device", DEVICES)
def test_stage_cost_keeps_torch_float32(device):
    z, u, ref, adj, offsets = random_case(2, 5, "paper", False, seed=3, spread=20.0)
    expected = stage_cost(z, u, ref, adj, offsets, PAPER.cost)

    def f32(x):
        return torch.as_tensor(np.asarray(x), dtype=torch.float32, device=device)

    got = stage_cost(f32(z), f32(u), f32(ref), adj, offsets, PAPER.cost)
    for name in NAMES:
        value = got.as_dict()[name]
        assert value.dtype == torch.float32
        np.testing.assert_allclose(
            array_api.to_numpy(value), getattr(expected, name), rtol=1e-3, atol=1e-2
        )


# ---------------------------------------------------------------------------------------------
# the term functions shared with the horizon cost


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 3])
def test_term_functions_equal_on_torch(device, batch):
    rng = np.random.default_rng(batch)
    n, p, h = 4, 3, 5
    own = rng.normal(size=(batch, n, p, h + 1, 6)) * 30.0 + 200.0
    others = rng.normal(size=(batch, n, h + 1, 6)) * 30.0 + 200.0
    views = rng.normal(size=(batch, n, n, h + 1, 6)) * 30.0 + 200.0
    adj = (rng.uniform(size=(batch, n, n)) < 0.5).astype(float)
    offsets = rng.normal(size=(batch, n, 6))
    t = {
        k: on(v, device)
        for k, v in dict(own=own, others=others, views=views, adj=adj, off=offsets).items()
    }
    close(anchored(t["own"], t["off"]), anchored(own, offsets))
    close(formation_error_sq(t["own"], t["others"], t["adj"]), formation_error_sq(own, others, adj))
    close(
        formation_error_sq(t["own"], t["views"], t["adj"], per_receiver=True),
        formation_error_sq(own, views, adj, per_receiver=True),
    )
    for per_receiver, senders in ((False, "others"), (True, "views")):
        expected = neighbour_moments(dict(others=others, views=views)[senders], adj, per_receiver)
        got = neighbour_moments(t[senders], t["adj"], per_receiver)
        for field in ("centre", "degree", "h_b", "h_bb"):
            close(getattr(got, field), getattr(expected, field))
        close(got.error_sq(t["own"]), expected.error_sq(own))
        index = np.array([0, 2, batch * n - 1])
        taken: NeighbourMoments = got.take(on(index, device))
        close(
            taken.error_sq(on(take_flat(own, index), device)),
            expected.take(index).error_sq(take_flat(own, index)),
        )
    close(
        velocity_error_sq(t["own"][..., 3:], t["others"][:, :, None, :, 3:]),
        velocity_error_sq(own[..., 3:], others[:, :, None, :, 3:]),
    )
    # separation over each receiver's views, with the torch mask
    mask = others_mask(batch, n, like=t["adj"])
    assert isinstance(mask, torch.Tensor) and mask.dtype == torch.float64
    np.testing.assert_array_equal(array_api.to_numpy(mask), others_mask(batch, n))
    assert others_mask(batch, n, like=adj).dtype == np.float64
    near = own[..., :3] * 0.01  # within d_s of each other
    near_views = views[..., :3] * 0.01
    expected = separation_sq(near, near_views, others_mask(batch, n), 10.0)
    assert expected.max() > 0
    close(separation_sq(on(near, device), on(near_views, device), mask, 10.0), expected)


# ---------------------------------------------------------------------------------------------
# proximity


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch, n_uav", [(1, 1), (1, 5), (4, 5), (2, 30)])
def test_pair_distances_and_nearest_equal_on_torch(device, batch, n_uav):
    rng = np.random.default_rng(n_uav)
    positions = rng.uniform(-40, 40, (batch, n_uav, 3))
    expected = pair_distances(positions)
    got = pair_distances(on(positions, device))
    close(got, expected)
    assert torch.isinf(torch.diagonal(got, dim1=1, dim2=2)).all()
    close(uav_pairs(on(positions, device), None), expected)
    for radius in (None, 15.0, 1e-3, 1e9):
        close(nearest_distance(got, radius), nearest_distance(expected, radius))
    close(gap_sq(got, 10.0), gap_sq(expected, 10.0))
    with pytest.raises(TypeError, match="numpy only"):
        sensed_pairs(on(positions, device), 10.0)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 2])
def test_torch_matrix_equals_the_grid_above_its_threshold(device, batch):
    """Above GRID_MIN_UAVS with a sensing radius numpy uses the grid and torch the all-pairs matrix:
    the nearest distances and the stage cost (separation included) agree."""
    scenario = swarm_scenario(100)
    radius = scenario.observation.sensing_radius
    assert radius is not None and scenario.formation.n_uav >= GRID_MIN_UAVS
    n = scenario.formation.n_uav
    rng = np.random.default_rng(batch)
    z = np.zeros((batch, n, 6))
    z[..., :2] = rng.uniform(0, 120, (batch, n, 2))  # crowded: many pairs closer than d_s
    z[:, :10, :2] = rng.uniform(1000, 5000, (batch, 10, 2))  # some with nobody within R
    z[..., 3:] = rng.normal(size=(batch, n, 3))
    grid = uav_pairs(z[..., :3], radius)
    assert isinstance(grid, SensedPairs)
    matrix = uav_pairs(on(z[..., :3], device), radius)
    assert isinstance(matrix, torch.Tensor) and tuple(matrix.shape) == (batch, n, n)
    expected_nearest = nearest_distance(grid, radius)
    assert np.isinf(expected_nearest).any() and np.isfinite(expected_nearest).any()
    close(nearest_distance(matrix, radius), expected_nearest)
    u, ref = rng.normal(size=(batch, n, 3)), rng.normal(size=(batch, n, 3))
    adj = np.broadcast_to(np.asarray(scenario.formation.adjacency, float), (batch, n, n))
    offsets = np.asarray(scenario.formation.offsets, float)
    expected = stage_cost(z, u, ref, adj, offsets, scenario.cost, pair_distance=grid)
    assert expected.separation.max() > 0
    got = stage_cost(
        on(z, device),
        on(u, device),
        on(ref, device),
        adj,
        offsets,
        scenario.cost,
        pair_distance=matrix,
    )
    assert_terms_equal(got, expected)
