"""Tests of the game cost J_i (eq. 6, SPEC §4): hand values, invariants, one definition."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env.config import PAPER_ADJACENCY, PAPER_OFFSETS, CostConfig
from uav_formation_env.core.cost import (
    anchored,
    formation_error_sq,
    horizon_cost,
    relative_offset_sign,
    stage_cost,
    velocity_error_sq,
)
from uav_formation_env.core.dynamics import rollout

# ------------------------------------------------------------------------------------------------
# A 3-UAV, H = 2, dt = 1 case computed by hand
# ------------------------------------------------------------------------------------------------
# adjacency (row = receiver): UAV0 <- 1 ; UAV1 <- 0, 2 ; UAV2 <- 0   (h_12 = 1 but h_21 = 0)
HAND_ADJ = np.array([[[0.0, 1.0, 0.0], [1.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])
HAND_OFFSETS = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [-1.0, 2.0, 0.0, 0.0, 0.0, 0.0],
        [-1.0, -2.0, 0.0, 0.0, 0.0, 0.0],
    ]
)
HAND_Z0 = np.array(
    [
        [
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            [-2.0, 2.0, 0.0, 1.0, 1.0, 0.0],
            [-1.0, -3.0, 1.0, 0.0, 0.0, 0.0],
        ]
    ]
)
# candidates (B=1, N=3, P=1, H=2, 3)
HAND_U = np.array(
    [
        [
            [[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]],
            [[[2.0, -2.0, 0.0], [0.0, 0.0, 0.0]]],
            [[[0.0, 0.0, 2.0], [0.0, 2.0, 0.0]]],
        ]
    ]
)
# broadcast neighbour predictions ẑ_j(k), k = 0, 1, 2 (k = 0 equals the measured state)
HAND_NEIGHBOURS = np.array(
    [
        [
            [[0.0, 0, 0, 1, 0, 0], [1, 0, 0, 1, 0, 0], [2, 0, 0, 1, 0, 0]],
            [[-2.0, 2, 0, 1, 1, 0], [-1, 3, 0, 1, 1, 0], [0, 4, 0, 1, 1, 0]],
            [[-1.0, -3, 1, 0, 0, 0], [-1, -3, 1, 0, 0, 0], [-1, -3, 1, 0, 0, 0]],
        ]
    ]
)
# v^d(t + k dt): (1,0,0), (1,0,0), (0,1,0) for every UAV
HAND_REF = np.broadcast_to(
    np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), (1, 3, 3, 3)
).copy()
HAND_WEIGHTS = CostConfig(q=2.0, r=3.0, m=5.0, n=7.0, horizon=2)

# UAV0: z(1) = (1,0,0, 1,0,0), z(2) = (1+1+1, 0, 0, 3,0,0) = (3,0,0, 3,0,0)
#   anchored ẑ_1 = ẑ_1 - (-1,2,0,...): (-1,0,0,1,1,0), (0,1,0,1,1,0), (1,2,0,1,1,0)
#   ε_01(0) = (1,0,0,0,-1,0) -> 2 ; ε_01(1) = (1,-1,0,0,-1,0) -> 3 ; ε_01(2) = (2,-2,0,2,-1,0) -> 13
#   formation 2 (2 + 3) = 10 ; terminal 5 * 13 = 65 ; energy 3 (0 + 4) = 12
#   velocity errors (0,0,0), (0,0,0), (3,-1,0) -> 7 * 10 = 70          J_0 = 157
# UAV1: z(1) = (-2+1+1, 2+1-1, 0, 3,-1,0) = (0,2,0, 3,-1,0), z(2) = (3,1,0, 3,-1,0)
#   anchored own: (-1,0,0,1,1,0), (1,0,0,3,-1,0), (4,-1,0,3,-1,0)
#   anchored ẑ_0: (0,0,0,1,0,0), (1,0,0,1,0,0), (2,0,0,1,0,0) ; anchored ẑ_2: (0,-1,1,0,0,0) always
#   ε_10: (-1,0,0,0,1,0) -> 2, (0,0,0,2,-1,0) -> 5, (2,-1,0,2,-1,0) -> 10
#   ε_12: (-1,1,-1,1,1,0) -> 5, (1,1,-1,3,-1,0) -> 13, (4,0,-1,3,-1,0) -> 27
#   formation 2 (2 + 5 + 5 + 13) = 50 ; terminal 5 (10 + 27) = 185 ; energy 3 (8 + 0) = 24
#   velocity errors (0,1,0) -> 1, (2,-1,0) -> 5, (3,-2,0) -> 13 : 7 * 19 = 133   J_1 = 392
# UAV2: z(1) = (-1,-3,1+1, 0,0,2), z(2) = (-1,-3+1,2+2, 0,2,2) = (-1,-2,4, 0,2,2)
#   anchored own: (0,-1,1,0,0,0), (0,-1,2,0,0,2), (0,0,4,0,2,2)
#   ε_20: (0,-1,1,-1,0,0) -> 3, (-1,-1,2,-1,0,2) -> 11, (-2,0,4,-1,2,2) -> 29
#   formation 2 (3 + 11) = 28 ; terminal 5 * 29 = 145 ; energy 3 (4 + 4) = 24
#   velocity errors (-1,0,0) -> 1, (-1,0,2) -> 5, (0,1,2) -> 5 : 7 * 11 = 77    J_2 = 274
HAND_EXPECTED = {
    "formation": [10.0, 50.0, 28.0],
    "energy": [12.0, 24.0, 24.0],
    "terminal": [65.0, 185.0, 145.0],
    "velocity": [70.0, 133.0, 77.0],
}
HAND_TOTAL = [157.0, 392.0, 274.0]


def hand_horizon_cost(**kwargs) -> dict[str, np.ndarray]:
    args = dict(
        candidates=HAND_U,
        z0=HAND_Z0,
        neighbour_trajectories=HAND_NEIGHBOURS,
        reference_preview=HAND_REF,
        adjacency=HAND_ADJ,
        offsets=HAND_OFFSETS,
        weights=HAND_WEIGHTS,
        dt=1.0,
    )
    args.update(kwargs)
    return horizon_cost(**args)


def test_hand_predictions() -> None:
    traj = rollout(HAND_Z0[:, :, None, :], HAND_U, 1.0)[0, :, 0]  # (N, H+1, 6)
    np.testing.assert_array_equal(traj[0, 1:], [[1, 0, 0, 1, 0, 0], [3, 0, 0, 3, 0, 0]])
    np.testing.assert_array_equal(traj[1, 1:], [[0, 2, 0, 3, -1, 0], [3, 1, 0, 3, -1, 0]])
    np.testing.assert_array_equal(traj[2, 1:], [[-1, -3, 2, 0, 0, 2], [-1, -2, 4, 0, 2, 2]])


def test_horizon_cost_by_hand() -> None:
    terms = hand_horizon_cost()
    for name, expected in HAND_EXPECTED.items():
        got = getattr(terms, name)
        assert got.shape == (1, 3, 1)
        np.testing.assert_allclose(got[0, :, 0], expected, rtol=1e-14, err_msg=name)
    np.testing.assert_allclose(terms.total[0, :, 0], HAND_TOTAL, rtol=1e-14)
    assert set(terms.as_dict()) == {"formation", "energy", "terminal", "velocity"}


def test_stage_cost_by_hand() -> None:
    # realised states z0, inputs u(0), references v^d(0)
    terms = stage_cost(
        HAND_Z0, HAND_U[:, :, 0, 0], HAND_REF[:, :, 0], HAND_ADJ, HAND_OFFSETS, HAND_WEIGHTS
    )
    # formation: UAV0 2*2 = 4 ; UAV1 2*(2 + 5) = 14 ; UAV2 2*3 = 6
    np.testing.assert_allclose(terms.formation[0], [4.0, 14.0, 6.0], rtol=1e-14)
    # energy: 3 * (0, 8, 4)
    np.testing.assert_allclose(terms.energy[0], [0.0, 24.0, 12.0], rtol=1e-14)
    # velocity at k = 0: 7 * (0, 1, 1)
    np.testing.assert_allclose(terms.velocity[0], [0.0, 7.0, 7.0], rtol=1e-14)
    np.testing.assert_array_equal(terms.terminal, 0.0)
    np.testing.assert_allclose(terms.total[0], [4.0, 45.0, 25.0], rtol=1e-14)


def test_adjacency_is_not_symmetrised() -> None:
    """Transposing H changes the cost (who-receives-from-whom matters)."""
    transposed = hand_horizon_cost(adjacency=np.swapaxes(HAND_ADJ, 1, 2))
    assert not np.allclose(transposed.formation[0, :, 0], HAND_EXPECTED["formation"])
    # UAV2 receives from UAV1 in the transpose: ε_21 = anchored own_2 - anchored ẑ_1
    # k=0: (0,-1,1,0,0,0)-(-1,0,0,1,1,0) -> 1+1+1+1+1 = 5
    # k=1: (0,-1,2,0,0,2)-(0,1,0,1,1,0) -> 4+4+1+1+4 = 14
    np.testing.assert_allclose(transposed.formation[0, 2, 0], 2.0 * (5.0 + 14.0), rtol=1e-14)


# ------------------------------------------------------------------------------------------------
# stage cost == k = 0 stage of the horizon cost (one definition)
# ------------------------------------------------------------------------------------------------


def random_case(
    rng: np.random.Generator, b: int = 2, n: int = 5, p: int = 3, h: int = 4, centre: float = 0.0
):
    z0 = np.concatenate(
        (centre + rng.normal(0, 10, (b, n, 3)), rng.normal(0, 20, (b, n, 3))), axis=-1
    )
    candidates = rng.uniform(-5, 5, (b, n, p, h, 3))
    neighbours = rollout(z0[:, :, None], rng.uniform(-5, 5, (b, n, 1, h, 3)), 0.2)[:, :, 0]
    reference = rng.normal(0, 20, (b, n, h + 1, 3))
    adjacency = (rng.random((b, n, n)) < 0.6).astype(float)
    for k in range(b):
        np.fill_diagonal(adjacency[k], 0.0)
    offsets = np.asarray(PAPER_OFFSETS)[:n] if n <= 5 else rng.normal(0, 20, (n, 6))
    return z0, candidates, neighbours, reference, adjacency, offsets


def test_stage_cost_is_first_stage_of_horizon_cost() -> None:
    rng = np.random.default_rng(10)
    z0, cand, neigh, ref, adj, offsets = random_case(rng, p=1, h=1)
    w = CostConfig(q=1.3, r=0.7, m=0.0, n=2.1, horizon=1)
    # make the k = 1 velocity term vanish: v^d(1) = predicted v(1); m = 0 drops the terminal term
    ref[:, :, 1] = z0[..., 3:] + cand[:, :, 0, 0] * 0.2
    hor = horizon_cost(cand, z0, neigh, ref, adj, offsets, w, 0.2)
    st = stage_cost(z0, cand[:, :, 0, 0], ref[:, :, 0], adj, offsets, w)
    for name in ("formation", "energy", "velocity"):
        np.testing.assert_allclose(
            getattr(hor, name)[..., 0], getattr(st, name), rtol=1e-10, atol=1e-9, err_msg=name
        )
    np.testing.assert_allclose(hor.total[..., 0], st.total, rtol=1e-10)


@pytest.mark.parametrize("mirrored", [False, True])
def test_stage_cost_equals_brute_force(mirrored: bool) -> None:
    rng = np.random.default_rng(12)
    z0, cand, _, ref, adj, offsets = random_case(rng, centre=1e3)
    u = cand[:, :, 0, 0]
    w = CostConfig(q=1.0, r=5.0, m=1.0, n=10.0)
    st = stage_cost(z0, u, ref[:, :, 0], adj, offsets, w, mirrored=mirrored)
    b, n = z0.shape[:2]
    sign = -1.0 if mirrored else 1.0
    for k in range(b):
        for i in range(n):
            form = sum(
                np.sum(((z0[k, i] - sign * offsets[i]) - (z0[k, j] - sign * offsets[j])) ** 2)
                for j in range(n)
                if adj[k, i, j]
            )
            assert st.formation[k, i] == pytest.approx(form, rel=1e-9)
            assert st.energy[k, i] == pytest.approx(5.0 * np.sum(u[k, i] ** 2), rel=1e-12)
            assert st.velocity[k, i] == pytest.approx(
                10.0 * np.sum((z0[k, i, 3:] - ref[k, i, 0]) ** 2), rel=1e-12
            )


# ------------------------------------------------------------------------------------------------
# perfect formation, offsets and their sign
# ------------------------------------------------------------------------------------------------


def formation_states(slots: np.ndarray, common: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """(1, N, 6): z_i = slot_i + common position, velocity = v^d."""
    z = slots.copy()
    z[:, :3] += common
    z[:, 3:] = velocity
    return z[None]


@pytest.mark.parametrize(
    "common", [(0.0, 0.0, 0.0), (1000.0, -850.0, 120.0), (1234.5678, 987.654321, 3.3)]
)
def test_zero_cost_in_perfect_formation(common: tuple[float, float, float]) -> None:
    offsets = np.asarray(PAPER_OFFSETS)
    adj = np.asarray(PAPER_ADJACENCY, dtype=float)[None]
    v_ref = np.array([20.0, 0.0, 0.0])
    z0 = formation_states(offsets, np.asarray(common), v_ref)
    h = 5
    zeros = np.zeros((1, 5, 1, h, 3))
    neighbours = rollout(z0[:, :, None], zeros, 0.2)[:, :, 0]
    ref = np.broadcast_to(v_ref, (1, 5, h + 1, 3))
    terms = horizon_cost(zeros, z0, neighbours, ref, adj, offsets, CostConfig(), 0.2)
    for name, value in terms.as_dict().items():
        assert np.abs(value).max() <= 1e-8, name
    st = stage_cost(
        z0, np.zeros((1, 5, 3)), np.broadcast_to(v_ref, (1, 5, 3)), adj, offsets, CostConfig()
    )
    assert np.abs(st.total).max() <= 1e-8


def test_offsets_are_zi_minus_zj_v_shape() -> None:
    """z_ij^d = z^d_i - z^d_j: the paper's V (UAV1 at the apex, pointing +x) costs 0 and the
    point-mirrored shape does not; the literal mirrored_offsets reading is the reverse."""
    offsets = np.asarray(PAPER_OFFSETS)
    adj = np.asarray(PAPER_ADJACENCY, dtype=float)[None]
    v_ref = np.array([20.0, 0.0, 0.0])
    ref = np.broadcast_to(v_ref, (1, 5, 3))
    u0 = np.zeros((1, 5, 3))
    common = np.array([300.0, 40.0, 0.0])
    v_shape = formation_states(offsets, common, v_ref)
    mirrored_shape = formation_states(-offsets, common, v_ref)
    # the V: UAV2 is behind and left (+y) of UAV1
    assert v_shape[0, 1, 0] < v_shape[0, 0, 0] and v_shape[0, 1, 1] > v_shape[0, 0, 1]
    w = CostConfig()
    assert np.abs(stage_cost(v_shape, u0, ref, adj, offsets, w).total).max() <= 1e-9
    assert stage_cost(mirrored_shape, u0, ref, adj, offsets, w).total.min() > 100.0
    assert (
        np.abs(stage_cost(mirrored_shape, u0, ref, adj, offsets, w, mirrored=True).total).max()
        <= 1e-9
    )
    assert stage_cost(v_shape, u0, ref, adj, offsets, w, mirrored=True).total.min() > 100.0
    # UAV1 <- {2, 4, 5} in the mirrored shape, by hand: pairs differ by 2 (z^d_i - z^d_j)
    # j=2: 2 * (0 - (-10), 0 - 20) -> 4 (100 + 400) = 2000 ; j=4: 4 (400 + 1600) = 8000 ;
    # j=5: 8000
    st = stage_cost(mirrored_shape, u0, ref, adj, offsets, w)
    assert st.formation[0, 0] == pytest.approx(18000.0, rel=1e-12)
    assert relative_offset_sign(False) == 1.0 and relative_offset_sign(True) == -1.0


def test_anchored_shapes() -> None:
    offsets = np.asarray(PAPER_OFFSETS)
    z = np.zeros((2, 5, 3, 4, 6))
    a = anchored(z, offsets)
    assert a.shape == z.shape
    np.testing.assert_array_equal(a[1, 3, 2, 1], -offsets[3])
    np.testing.assert_array_equal(anchored(z, offsets, mirrored=True)[0, 4, 0, 0], offsets[4])


# ------------------------------------------------------------------------------------------------
# formation_error_sq against brute force
# ------------------------------------------------------------------------------------------------


def brute_formation(own: np.ndarray, others: np.ndarray, adj: np.ndarray) -> np.ndarray:
    b, n = own.shape[:2]
    out = np.zeros(own.shape[:-1])
    for k in range(b):
        for i in range(n):
            for j in range(n):
                if adj[k, i, j]:
                    out[k, i] += np.sum((own[k, i] - others[k, j]) ** 2, axis=-1)
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_formation_error_sq_matches_brute_force_at_1e3(seed: int) -> None:
    rng = np.random.default_rng(seed)
    b, n, p, h1 = 3, 6, 4, 5
    # positions around 1 km, formation errors of metres, velocities around 20 m/s
    pos = 1e3 + rng.normal(0, 10, (b, n, 1, 1, 3))
    own = np.concatenate(
        (pos + rng.normal(0, 10, (b, n, p, h1, 3)), 20 + rng.normal(0, 3, (b, n, p, h1, 3))), -1
    )
    others = own[:, :, 0] + rng.normal(0, 5, (b, n, h1, 6))
    adj = (rng.random((b, n, n)) < 0.5).astype(float)
    for k in range(b):
        np.fill_diagonal(adj[k], 0.0)
    got = formation_error_sq(own, others, adj)
    assert got.shape == (b, n, p, h1)
    np.testing.assert_allclose(got, brute_formation(own, others, adj), rtol=1e-9, atol=0)
    # others without a horizon axis (the stage-cost use)
    got2 = formation_error_sq(own[:, :, 0, 0], own[:, :, 0, 0], adj)
    np.testing.assert_allclose(
        got2, brute_formation(own[:, :, 0, 0], own[:, :, 0, 0], adj), rtol=1e-9, atol=0
    )


def test_formation_error_sq_relative_accuracy_near_formation_at_1e3() -> None:
    rng = np.random.default_rng(0)
    b, n, p, h1 = 3, 5, 4, 3
    centre = np.array([1e3, -1e3, 100.0, 20.0, 0.0, 0.0])  # 1 km away at 20 m/s
    own = centre + 0.01 * rng.standard_normal((b, n, p, h1, 6))
    others = centre + 0.01 * rng.standard_normal((b, n, h1, 6))
    adj = np.ones((b, n, n)) - np.eye(n)
    np.testing.assert_allclose(
        formation_error_sq(own, others, adj), brute_formation(own, others, adj), rtol=1e-9, atol=0
    )


# ------------------------------------------------------------------------------------------------
# structure: candidates, weights, adjacency
# ------------------------------------------------------------------------------------------------


def test_p_candidates_equal_separate_calls() -> None:
    rng = np.random.default_rng(20)
    z0, cand, neigh, ref, adj, offsets = random_case(rng, p=6, h=5, centre=500.0)
    w = CostConfig()
    together = horizon_cost(cand, z0, neigh, ref, adj, offsets, w, 0.2)
    assert together.total.shape == (2, 5, 6)
    for k in range(6):
        alone = horizon_cost(cand[:, :, k : k + 1], z0, neigh, ref, adj, offsets, w, 0.2)
        for name in ("formation", "energy", "terminal", "velocity"):
            np.testing.assert_allclose(
                getattr(together, name)[..., k], getattr(alone, name)[..., 0], rtol=1e-10, atol=1e-9
            )
    # candidates really differ, so the comparison is not vacuous
    assert np.ptp(together.total, axis=-1).min() > 1.0


def test_weights_scale_terms_linearly() -> None:
    rng = np.random.default_rng(21)
    z0, cand, neigh, ref, adj, offsets = random_case(rng)
    unit = horizon_cost(cand, z0, neigh, ref, adj, offsets, CostConfig(q=1, r=1, m=1, n=1), 0.2)
    assert min(float(v.min()) for v in unit.as_dict().values()) > 0
    w = CostConfig(q=0.5, r=3.0, m=7.0, n=0.25)
    scaled = horizon_cost(cand, z0, neigh, ref, adj, offsets, w, 0.2)
    np.testing.assert_allclose(scaled.formation, 0.5 * unit.formation, rtol=1e-12)
    np.testing.assert_allclose(scaled.energy, 3.0 * unit.energy, rtol=1e-12)
    np.testing.assert_allclose(scaled.terminal, 7.0 * unit.terminal, rtol=1e-12)
    np.testing.assert_allclose(scaled.velocity, 0.25 * unit.velocity, rtol=1e-12)
    double = horizon_cost(cand, z0, neigh, ref, adj, offsets, CostConfig(q=2, r=2, m=2, n=2), 0.2)
    np.testing.assert_allclose(double.total, 2.0 * unit.total, rtol=1e-12)
    # each weight only scales its own term
    only_q = horizon_cost(cand, z0, neigh, ref, adj, offsets, CostConfig(q=1, r=0, m=0, n=0), 0.2)
    np.testing.assert_allclose(only_q.total, unit.formation, rtol=1e-12)


def test_adjacency_zero_row_gives_zero_formation_terms() -> None:
    rng = np.random.default_rng(22)
    z0, cand, neigh, ref, adj, offsets = random_case(rng)
    w = CostConfig()
    full = horizon_cost(cand, z0, neigh, ref, adj, offsets, w, 0.2)
    lonely = adj.copy()
    lonely[:, 2, :] = 0.0  # UAV 2 receives from nobody (a singleton after a topology split)
    cut = horizon_cost(cand, z0, neigh, ref, lonely, offsets, w, 0.2)
    np.testing.assert_array_equal(cut.formation[:, 2], 0.0)
    np.testing.assert_array_equal(cut.terminal[:, 2], 0.0)
    np.testing.assert_allclose(cut.energy[:, 2], full.energy[:, 2], rtol=1e-14)
    np.testing.assert_allclose(cut.velocity[:, 2], full.velocity[:, 2], rtol=1e-14)
    assert full.formation[:, 2].min() > 0
    # other rows are unchanged
    others = [0, 1, 3, 4]
    np.testing.assert_allclose(cut.total[:, others], full.total[:, others], rtol=1e-12)
    st = stage_cost(z0, cand[:, :, 0, 0], ref[:, :, 0], lonely, offsets, w)
    np.testing.assert_array_equal(st.formation[:, 2], 0.0)
    assert st.energy[:, 2].min() > 0 and st.velocity[:, 2].min() > 0


def test_velocity_error_sq() -> None:
    assert float(velocity_error_sq(np.array([3.0, 4.0, 0.0]), np.zeros(3))) == 25.0
    v = np.ones((2, 4, 3))
    np.testing.assert_array_equal(velocity_error_sq(v, np.array([1.0, 0.0, 3.0])), 5.0)


def test_horizon_uses_the_given_dt() -> None:
    """Same candidates, different dt: predictions differ, so costs differ (dt is not hard-coded)."""
    a = hand_horizon_cost()
    b = hand_horizon_cost(dt=0.5)
    np.testing.assert_array_equal(a.energy, b.energy)
    assert not np.allclose(a.velocity, b.velocity)


def test_cost_config_is_used_not_defaults() -> None:
    w = dataclasses.replace(HAND_WEIGHTS, q=0.0)
    terms = hand_horizon_cost(weights=w)
    np.testing.assert_array_equal(terms.formation, 0.0)
    np.testing.assert_allclose(terms.terminal[0, :, 0], HAND_EXPECTED["terminal"], rtol=1e-14)
