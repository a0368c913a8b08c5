"""Tests of the game cost J_i (eq. 6, docs/model.md §4): hand values, invariants, one definition."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env.config import PAPER_ADJACENCY, PAPER_OFFSETS, CostConfig, FormationConfig
from uav_formation_env.core.cost import (
    anchored,
    formation_error_sq,
    horizon_cost,
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
# separation = 0: the hand values are the paper's J_i (the separation term has its own tests below)
HAND_WEIGHTS = CostConfig(q=2.0, r=3.0, m=5.0, n=7.0, horizon=2, separation=0.0)

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
    assert set(terms.as_dict()) == {
        "formation",
        "energy",
        "terminal",
        "velocity",
        "separation",
        "obstacle",
    }
    np.testing.assert_array_equal(terms.separation, 0.0)  # switched off in HAND_WEIGHTS


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
    # separation = 0: its k = 1 summand cannot be made to vanish here; its stage/horizon
    # consistency is test_horizon_separation_is_the_sum_of_stage_separations
    w = CostConfig(q=1.3, r=0.7, m=0.0, n=2.1, horizon=1, separation=0.0)
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
    # the literal mirrored reading reaches the core as negated offsets (FormationConfig)
    st = stage_cost(z0, u, ref[:, :, 0], adj, -offsets if mirrored else offsets, w)
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
    literal = FormationConfig(mirrored_offsets=True).slot_offsets  # the literal reading
    assert np.abs(stage_cost(mirrored_shape, u0, ref, adj, literal, w).total).max() <= 1e-9
    assert stage_cost(v_shape, u0, ref, adj, literal, w).total.min() > 100.0
    # UAV1 <- {2, 4, 5} in the mirrored shape, by hand: pairs differ by 2 (z^d_i - z^d_j)
    # j=2: 2 * (0 - (-10), 0 - 20) -> 4 (100 + 400) = 2000 ; j=4: 4 (400 + 1600) = 8000 ;
    # j=5: 8000
    st = stage_cost(mirrored_shape, u0, ref, adj, offsets, w)
    assert st.formation[0, 0] == pytest.approx(18000.0, rel=1e-12)
    np.testing.assert_array_equal(literal, -offsets)


def test_anchored_shapes() -> None:
    offsets = np.asarray(PAPER_OFFSETS)
    z = np.zeros((2, 5, 3, 4, 6))
    a = anchored(z, offsets)
    assert a.shape == z.shape
    np.testing.assert_array_equal(a[1, 3, 2, 1], -offsets[3])
    np.testing.assert_array_equal(anchored(z, -offsets)[0, 4, 0, 0], offsets[4])


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
    ones = CostConfig(q=1, r=1, m=1, n=1, separation=1)
    unit = horizon_cost(cand, z0, neigh, ref, adj, offsets, ones, 0.2)
    paper_terms = ("formation", "energy", "terminal", "velocity")
    assert min(float(getattr(unit, name).min()) for name in paper_terms) > 0
    assert unit.separation.max() > 0  # some UAVs of the random case are closer than d_s = 10 m
    w = CostConfig(q=0.5, r=3.0, m=7.0, n=0.25, separation=2.5)
    scaled = horizon_cost(cand, z0, neigh, ref, adj, offsets, w, 0.2)
    np.testing.assert_allclose(scaled.formation, 0.5 * unit.formation, rtol=1e-12)
    np.testing.assert_allclose(scaled.energy, 3.0 * unit.energy, rtol=1e-12)
    np.testing.assert_allclose(scaled.terminal, 7.0 * unit.terminal, rtol=1e-12)
    np.testing.assert_allclose(scaled.velocity, 0.25 * unit.velocity, rtol=1e-12)
    np.testing.assert_allclose(scaled.separation, 2.5 * unit.separation, rtol=1e-12)
    twos = CostConfig(q=2, r=2, m=2, n=2, separation=2)
    double = horizon_cost(cand, z0, neigh, ref, adj, offsets, twos, 0.2)
    np.testing.assert_allclose(double.total, 2.0 * unit.total, rtol=1e-12)
    # each weight only scales its own term
    only_q = CostConfig(q=1, r=0, m=0, n=0, separation=0)
    only_q_terms = horizon_cost(cand, z0, neigh, ref, adj, offsets, only_q, 0.2)
    np.testing.assert_allclose(only_q_terms.total, unit.formation, rtol=1e-12)
    only_s = CostConfig(q=0, r=0, m=0, n=0, separation=1)
    only_s_terms = horizon_cost(cand, z0, neigh, ref, adj, offsets, only_s, 0.2)
    np.testing.assert_allclose(only_s_terms.total, unit.separation, rtol=1e-12)


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


# ------------------------------------------------------------------------------------------------
# separation term (not in the paper: docs/deviations.md §5)
# ------------------------------------------------------------------------------------------------


def states_at(*positions: tuple[float, float, float], velocity=(20.0, 0.0, 0.0)) -> np.ndarray:
    """(1, N, 6) states at the given positions with a common velocity."""
    return np.array([[(*p, *velocity) for p in positions]], dtype=float)


def stage_separation(z: np.ndarray, weights: CostConfig, adjacency=None) -> np.ndarray:
    n = z.shape[1]
    adjacency = np.zeros((1, n, n)) if adjacency is None else adjacency
    zeros = np.zeros((1, n, 3))
    st = stage_cost(z, zeros, z[..., 3:], adjacency, np.zeros((n, 6)), weights)
    return st.separation[0]


def test_separation_by_hand_inside_and_outside_d_s() -> None:
    w = CostConfig(separation=2.0, separation_distance=8.0)
    # 5 m apart (3-4-5 triangle): each UAV pays 2 (8 - 5)^2 = 18
    np.testing.assert_allclose(stage_separation(states_at((0, 0, 0), (3, 4, 0)), w), [18.0, 18.0])
    # 10 m apart: outside d_s, no penalty; exactly d_s apart: none either
    np.testing.assert_array_equal(stage_separation(states_at((0, 0, 0), (6, 8, 0)), w), 0.0)
    np.testing.assert_array_equal(stage_separation(states_at((0, 0, 0), (0, 8, 0)), w), 0.0)
    # three UAVs: the sum over every other UAV, whatever the adjacency (sensed, not received)
    z = states_at((0, 0, 0), (3, 4, 0), (0, 0, 6))
    far = (8.0 - np.sqrt(61.0)) ** 2  # UAV1-UAV2 distance sqrt(9 + 16 + 36)
    expected = 2.0 * np.array([9.0 + 4.0, 9.0 + far, 4.0 + far])
    np.testing.assert_allclose(stage_separation(z, w), expected, rtol=1e-14)
    full = np.ones((1, 3, 3)) - np.eye(3)
    np.testing.assert_allclose(stage_separation(z, w, full), expected, rtol=1e-14)
    # the weight scales it; s = 0 or d_s = 0 switches it off (the paper's J_i)
    w_off = [CostConfig(separation=0.0), CostConfig(separation_distance=0.0)]
    for off in w_off:
        np.testing.assert_array_equal(stage_separation(z, off), 0.0)
    doubled = CostConfig(separation=4.0, separation_distance=8.0)
    np.testing.assert_allclose(stage_separation(z, doubled), 2.0 * expected, rtol=1e-14)


def test_separation_over_the_horizon_by_hand() -> None:
    """H = 1, δ = 1: UAV0 at 0 flying +x at 1 m/s, UAV1 parked 6 m ahead. With u(0) = (2, 0, 0),
    p0(1) = 0 + 1 + ½ 2 = 2: distances 6 then 4, penalties (8-6)² + (8-4)² = 20 (k = 0 and 1)."""
    w = CostConfig(q=0.0, r=0.0, m=0.0, n=0.0, separation=3.0, separation_distance=8.0, horizon=1)
    z0 = np.array([[[0.0, 0, 0, 1, 0, 0], [6.0, 0, 0, 0, 0, 0]]])
    neighbours = np.repeat(z0[:, :, None], 2, axis=2)  # UAV1 stays; UAV0's own row is not read
    cand = np.zeros((1, 2, 1, 1, 3))
    cand[0, 0, 0, 0] = (2.0, 0.0, 0.0)
    ref = np.zeros((1, 2, 2, 3))
    terms = horizon_cost(cand, z0, neighbours, ref, np.zeros((1, 2, 2)), np.zeros((2, 6)), w, 1.0)
    assert terms.separation[0, 0, 0] == pytest.approx(3.0 * 20.0, rel=1e-14)
    assert terms.total[0, 0, 0] == pytest.approx(60.0, rel=1e-14)
    # UAV1 (no input) sees UAV0's broadcast row: the same positions at k = 0 and 1 -> (8-6)² twice
    assert terms.separation[0, 1, 0] == pytest.approx(3.0 * 8.0, rel=1e-14)


def test_separation_is_zero_in_the_paper_formation() -> None:
    offsets = np.asarray(PAPER_OFFSETS)
    gaps = np.linalg.norm(offsets[:, None, :3] - offsets[None, :, :3], axis=-1)
    spacing = gaps[~np.eye(5, dtype=bool)].min()
    assert spacing == pytest.approx(np.sqrt(500.0))  # 22.4 m, far outside d_s
    assert CostConfig().separation_distance < spacing
    v_ref = np.array([0.0, 20.0, 0.0])
    z0 = formation_states(offsets, np.array([700.0, 300.0, 0.0]), v_ref)
    adj = np.asarray(PAPER_ADJACENCY, dtype=float)[None]
    st = stage_cost(
        z0, np.zeros((1, 5, 3)), np.broadcast_to(v_ref, (1, 5, 3)), adj, offsets, CostConfig()
    )
    np.testing.assert_array_equal(st.separation, 0.0)
    neighbours = rollout(z0[:, :, None], np.zeros((1, 5, 1, 5, 3)), 0.2)[:, :, 0]
    cand = np.random.default_rng(0).uniform(-5, 5, (1, 5, 8, 5, 3))  # any input in the box
    ref = np.broadcast_to(v_ref, (1, 5, 6, 3))
    terms = horizon_cost(cand, z0, neighbours, ref, adj, offsets, CostConfig(), 0.2)
    np.testing.assert_array_equal(terms.separation, 0.0)


def close_case(rng: np.random.Generator, b: int = 2, n: int = 5, p: int = 7, h: int = 5):
    """UAVs a few metres apart around 800 m (so the separation term is active), with plans."""
    z0 = np.concatenate(
        (800.0 + rng.normal(0, 4, (b, n, 3)), 20.0 + rng.normal(0, 2, (b, n, 3))), axis=-1
    )
    plans = rng.uniform(-5, 5, (b, n, 1, h, 3))
    neighbours = rollout(z0[:, :, None], plans, 0.2)[:, :, 0]
    candidates = rng.uniform(-5, 5, (b, n, p, h, 3))
    reference = rng.normal(0, 20, (b, n, h + 1, 3))
    adjacency = (rng.random((b, n, n)) < 0.6).astype(float)
    adjacency[:, np.arange(n), np.arange(n)] = 0.0
    return z0, plans, neighbours, candidates, reference, adjacency


def test_horizon_separation_is_the_sum_of_stage_separations() -> None:
    """One definition: when every UAV flies its own candidate and broadcasts it, the horizon
    separation of UAV i is Σ_k of the stage separation at the joint predicted states z(k)."""
    rng = np.random.default_rng(30)
    z0, _, _, cand, ref, adj = close_case(rng, p=1)
    offsets = np.asarray(PAPER_OFFSETS)
    w = CostConfig()
    joint = rollout(z0[:, :, None], cand, 0.2)[:, :, 0]  # (B, N, H+1, 6)
    hor = horizon_cost(cand, z0, joint, ref, adj, offsets, w, 0.2)
    stages = sum(
        stage_cost(joint[:, :, k], cand[:, :, 0, 0], ref[:, :, k], adj, offsets, w).separation
        for k in range(joint.shape[2])
    )
    assert stages.min() > 0  # the UAVs are close: the term is active for everyone
    np.testing.assert_allclose(hor.separation[..., 0], stages, rtol=1e-12)


def brute_separation(z0, cand, others, mask, w, dt=0.2) -> np.ndarray:
    own = rollout(z0[:, :, None], cand, dt)[..., :3]  # (B, R, P, H+1, 3)
    b, r, p = own.shape[:3]
    out = np.zeros((b, r, p))
    for k in range(b):
        for i in range(r):
            for j in range(others.shape[2]):
                if mask[k, i, j]:
                    d = np.linalg.norm(own[k, i] - others[k, i, j][None], axis=-1)
                    out[k, i] += np.sum(np.maximum(w.separation_distance - d, 0.0) ** 2, axis=-1)
    return w.separation * out


def test_per_receiver_separation_against_brute_force() -> None:
    rng = np.random.default_rng(31)
    z0, plans, _, cand, ref, adj = close_case(rng)
    # receiver i predicts neighbours with their plans and everyone else with zero inputs
    received = np.where(adj[..., None, None] > 0, plans[:, None, :, 0], 0.0)
    views = rollout(np.broadcast_to(z0[:, None], received.shape[:3] + (6,)), received, 0.2)
    w = CostConfig(separation=7.0, separation_distance=9.0)
    terms = horizon_cost(cand, z0, views, ref, adj, np.asarray(PAPER_OFFSETS), w, 0.2)
    mask = np.ones((2, 5, 5)) - np.eye(5)
    expected = brute_separation(z0, cand, views[..., :3], mask, w)
    assert expected.min() > 0
    np.testing.assert_allclose(terms.separation, expected, rtol=1e-12)


@pytest.mark.parametrize("seed", [32, 33, 34])
def test_population_cost_equals_the_direct_horizon_cost_with_close_uavs(seed: int) -> None:
    """The fast population evaluation (quadratic coefficients + the separation term of the pairs
    that can be active in the box) equals the direct J_i for random candidates in the box."""
    from uav_formation_env.core.cost import prepare_horizon_cost

    rng = np.random.default_rng(seed)
    z0, _, neighbours, _, ref, adj = close_case(rng, b=2, n=5)
    z0[0, 4, :3] += 300.0  # one UAV far away: its pairs cannot become active
    neighbours[0, 4, :, :3] += 300.0
    half = rng.uniform(0.5, 5.0, (2, 5, 3))
    cand = rng.uniform(-1, 1, (2, 5, 40, 5, 3)) * half[:, :, None, None, :]
    prepared = prepare_horizon_cost(
        z0, neighbours, ref, adj, np.asarray(PAPER_OFFSETS), CostConfig(), 0.2
    )
    direct = prepared.terms(cand)
    assert direct.separation.max() > 100.0 and (direct.separation == 0).any()
    screened = prepared.quadratic(half_width=half)
    np.testing.assert_allclose(screened.total(cand), direct.total, rtol=1e-10, atol=1e-8)
    unscreened = prepared.quadratic()  # every pair: exact for any candidate
    np.testing.assert_allclose(
        unscreened.total(3 * cand), prepared.terms(3 * cand).total, rtol=1e-10
    )
    # the screen drops pairs (UAV 4 of copy 0 is 300 m away) but keeps every active one
    part = prepared.separation_part(half)
    assert part.others.shape[0] < prepared.separation_part().others.shape[0]
    assert 4 not in part.rows  # copy 0, UAV 4: nobody within reach
    # taking the triggered problems keeps both parts consistent
    index = np.array([9, 0, 4, 3])
    flat = cand.reshape(10, 40, 5, 3)[index][None]
    np.testing.assert_allclose(
        screened.take(index).total(flat)[0],
        direct.total.reshape(10, 40)[index],
        rtol=1e-10,
        atol=1e-8,
    )
    np.testing.assert_allclose(
        prepared.take(index).terms(flat).total[0], direct.total.reshape(10, 40)[index], rtol=1e-12
    )


def test_separation_off_leaves_the_paper_cost_unchanged() -> None:
    rng = np.random.default_rng(35)
    z0, _, neighbours, cand, ref, adj = close_case(rng)
    offsets = np.asarray(PAPER_OFFSETS)
    on = horizon_cost(cand, z0, neighbours, ref, adj, offsets, CostConfig(), 0.2)
    off = horizon_cost(cand, z0, neighbours, ref, adj, offsets, CostConfig(separation=0.0), 0.2)
    np.testing.assert_array_equal(off.separation, 0.0)
    for name in ("formation", "energy", "terminal", "velocity"):
        np.testing.assert_array_equal(getattr(on, name), getattr(off, name))
    np.testing.assert_allclose(on.total - off.total, on.separation, rtol=1e-9)


def test_superposed_rollout_equals_rollout() -> None:
    from uav_formation_env.core.cost import state_response, superposed_rollout

    rng = np.random.default_rng(36)
    z0 = np.concatenate((rng.normal(0, 300, (2, 5, 5, 3)), rng.normal(0, 20, (2, 5, 5, 3))), -1)
    inputs = rng.uniform(-5, 5, (2, 5, 5, 4, 3))
    np.testing.assert_allclose(
        superposed_rollout(z0, inputs, 0.2), rollout(z0, inputs, 0.2), rtol=1e-13, atol=1e-12
    )
    response = state_response(4, 0.2)
    assert response.shape == (6, 30) and not response.flags.writeable
    np.testing.assert_array_equal(response[:, :6], np.eye(6))  # k = 0 is z0 itself
