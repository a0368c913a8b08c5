"""Exact best responses: every UAV's horizon problem solved as a box-constrained QP.

The prediction is affine in UAV i's input sequence U_i and J_i is a sum of squares of affine
functions of it, so apart from the clearance terms (separation, obstacle) J_i is exactly quadratic
in x = U_i flattened (n = 3H components, index ``3k + c`` for step k and axis c):

    J_i(x) = c + gᵀx + xᵀQx + sep(x),   box: lower <= x <= upper,

with ``sep`` the sum of the clearance terms.

The coefficients are not written down a second time: :meth:`~uav_formation_env.core.cost.
HorizonCost.quadratic` identifies them from ``1 + 2n + n(n-1)/2`` (136 for H = 5) evaluations of
the one definition of J_i. ``Q >= r I`` (the energy term), so the quadratic part is strictly convex
and its minimiser over the box is unique; :func:`solve_box_qp` finds it exactly (to rounding) with
a batched primal active-set method, which terminates finitely.

The clearance terms ``sep >= 0`` are not convex. They are zero unless two UAVs can come closer than
d_s, or a UAV within an obstacle's clearance radius, inside the box
(:meth:`~uav_formation_env.core.cost.HorizonCost.separation_part` and ``obstacle_part`` keep only
such pairs, none in formation flight away from obstacles). Since ``J_i >= c + gᵀx + xᵀQx``
everywhere, a QP solution with ``sep = 0`` is the exact global minimiser of J_i over the box. Where
``sep > 0`` at the QP solution (rare) :func:`best_response` refines it by a few sequential box-QP
steps on the full J_i (model Hessian 2Q, gradient of sep by central differences of the one
definition, Armijo backtracking): that gives a local minimiser, flagged ``exact = False``, with
``lower_bound`` = the QP minimum, a certified lower bound of the true minimum.

Shapes: B copies, N UAVs, H horizon steps, n = 3H, M flattened problems.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uav_formation_env.core.cost import QuadraticCost
from uav_formation_env.policies.broadcast import HorizonProblems

__all__ = [
    "BestResponse",
    "BoxQPResult",
    "ExactConfig",
    "best_response",
    "box_of",
    "identification_evaluations",
    "solve_box_qp",
]

KKT_TOL = 1e-11  # relative tolerance of the sign test on the multipliers [-]
REFINE_STEPS = 20  # sequential box-QP steps on the full J_i where a clearance term is active
ARMIJO = 1e-4  # sufficient-decrease constant of the refinement's line search [-]
FD_STEP = 1e-6  # central-difference step of the clearance terms' gradient [m/s^2]


@dataclass(frozen=True)
class ExactConfig:
    """``NashDMPCPolicy(optimizer=ExactConfig())`` (or ``"exact"``): the paper's one best response
    per step against the neighbours' shifted warm starts, solved exactly by :func:`best_response`
    instead of by PIO / LFPIO. It has no parameters: the solution does not depend on any."""


def identification_evaluations(horizon: int) -> int:
    """Direct evaluations of J_i that identifying its quadratic form costs: 1 + 2n + n(n-1)/2."""
    n = 3 * horizon
    return 1 + 2 * n + n * (n - 1) // 2


@dataclass(frozen=True)
class BoxQPResult:
    """Solutions of M box-constrained QPs.

    Attributes:
        x: (M, n) minimisers.
        value: (M,) ``0.5 xᵀHx + gᵀx`` at x.
        iterations: (M,) active-set iterations (linear solves) spent.
        converged: (M,) bool, KKT conditions met within the iteration cap.
        kkt_residual: (M,) ``max |x - clip(x - ∇)|``, the projected-gradient residual.
    """

    x: np.ndarray
    value: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    kkt_residual: np.ndarray


def solve_box_qp(
    hessian: np.ndarray,
    linear: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    x0: np.ndarray | None = None,
    max_iter: int | None = None,
) -> BoxQPResult:
    """Minimise ``0.5 xᵀHx + gᵀx`` s.t. ``lower <= x <= upper`` exactly, for M problems at once.

    Primal active-set method (Nocedal & Wright, Alg. 16.3) for strictly convex H, vectorised over
    the problems (the loop runs over iterations; finished problems drop out). From a feasible
    start it alternates: minimise over the free components with the working set held at its
    bounds; if that point is infeasible, step to the first bound it crosses and add every bound
    hit; if feasible, stop when every working bound's multiplier has the right sign, else release
    the most wrongly signed one. The objective decreases strictly on each non-zero step and each
    working set is visited at most once, so it terminates finitely (at most ~2n iterations in
    practice). Components with ``lower == upper`` stay fixed.

    Args:
        hessian: (M, n, n) symmetric positive definite H.
        linear: (M, n) g.
        lower: (M, n) lower bounds, finite.
        upper: (M, n) upper bounds, finite, ``>= lower``.
        x0: (M, n) start (clipped into the box); None: the unconstrained minimiser, clipped.
        max_iter: iteration cap (None: 10 n + 10); problems still running are ``converged=False``.

    Returns:
        :class:`BoxQPResult`.
    """
    hessian, linear = np.asarray(hessian, dtype=float), np.asarray(linear, dtype=float)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    m, n = linear.shape
    if np.any(upper < lower):
        raise ValueError("every upper bound must be >= its lower bound")
    if x0 is None:
        x0 = np.linalg.solve(hessian, -linear[..., None])[..., 0]
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    fixed = lower == upper
    at_low = (x <= lower) & ~fixed
    at_up = (x >= upper) & ~fixed
    iterations = np.zeros(m, dtype=np.int64)
    running = np.ones(m, dtype=bool)
    cap = 10 * n + 10 if max_iter is None else int(max_iter)
    for _ in range(cap):
        idx = np.flatnonzero(running)
        if idx.size == 0:
            break
        iterations[idx] += 1
        h, g, lo, hi = hessian[idx], linear[idx], lower[idx], upper[idx]
        xi, low_i, up_i = x[idx], at_low[idx], at_up[idx]
        bound = low_i | up_i | fixed[idx]
        y = _subproblem(h, g, np.where(bound, xi, 0.0), ~bound)
        step = y - xi
        # Largest feasible fraction of the step, per free component and then per problem.
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(
                step < 0.0, (lo - xi) / step, np.where(step > 0.0, (hi - xi) / step, np.inf)
            )
        ratio = np.where(bound, np.inf, np.maximum(ratio, 0.0))
        alpha = np.minimum(ratio.min(axis=1), 1.0)
        blocked = alpha < 1.0
        xi = np.where(blocked[:, None], xi + alpha[:, None] * step, y)
        # Every bound reached at this fraction joins the working set at its exact value.
        hit = blocked[:, None] & (ratio <= alpha[:, None])
        hit_low, hit_up = hit & (step < 0.0), hit & (step > 0.0)
        xi = np.where(hit_low, lo, np.where(hit_up, hi, xi))
        low_i |= hit_low
        up_i |= hit_up
        # Feasible subproblem minimiser: test the multipliers of the working bounds.
        grad = np.einsum("mij,mj->mi", h, xi) + g
        scale = np.maximum(np.abs(grad).max(axis=1), np.abs(g).max(axis=1)) + 1.0
        wrong = np.where(low_i, -grad, np.where(up_i, grad, -np.inf))
        worst = wrong.argmax(axis=1)
        release = ~blocked & (wrong.max(axis=1) > KKT_TOL * scale)
        rows = np.flatnonzero(release)
        low_i[rows, worst[rows]] = False
        up_i[rows, worst[rows]] = False
        x[idx], at_low[idx], at_up[idx] = xi, low_i, up_i
        running[idx[~blocked & ~release]] = False
    grad = np.einsum("mij,mj->mi", hessian, x) + linear
    return BoxQPResult(
        x=x,
        value=0.5 * np.einsum("mi,mi->m", grad + linear, x),
        iterations=iterations,
        converged=~running,
        kkt_residual=np.abs(x - np.clip(x - grad, lower, upper)).max(axis=1),
    )


def _subproblem(h: np.ndarray, g: np.ndarray, x_bound: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Minimiser over the free components with the others held at ``x_bound``.

    Rows and columns of bound components are replaced by the identity, so one batched solve of
    the (M, n, n) system gives ``H_FF y_F = -(g_F + H_FB x_B)`` and ``y_B = x_B``.
    """
    pair = free[:, :, None] & free[:, None, :]
    system = np.where(pair, h, 0.0)
    diag = np.arange(h.shape[-1])
    system[:, diag, diag] = np.where(free, system[:, diag, diag], 1.0)
    rhs = np.where(free, -(g + np.einsum("mij,mj->mi", h, x_bound)), x_bound)
    return np.linalg.solve(system, rhs[..., None])[..., 0]


def box_of(half_width: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """The box ``|x_c| <= w_c`` of the flattened sequences, held over the horizon.

    Args:
        half_width: (..., 3) per-axis half width [m/s^2].
        horizon: H.

    Returns:
        ``(lower, upper)``, each (..., 3H), ordered as the flattened (H, 3) sequence.
    """
    upper = np.tile(np.asarray(half_width, dtype=float), horizon)
    return -upper, upper


@dataclass(frozen=True)
class BestResponse:
    """Every UAV's best response to the plans its problem was built from (leading dims (B, N)).

    Attributes:
        x: (B, N, H, 3) the minimising sequences [m/s^2], inside the box.
        cost: (B, N) J_i(x) by the direct evaluation of the one definition [-].
        lower_bound: (B, N) the minimum of J_i's quadratic part over the box, a lower bound of
            min J_i (equal to it, up to rounding, where ``exact``) [-].
        exact: (B, N) bool, x is the global minimiser (the clearance terms vanish at the QP
            solution and the QP converged); False where the refinement gave a local minimiser.
        qp_iterations: (B, N) active-set iterations of the QP.
        evaluations: (B, N) evaluations of J_i spent: the identification (136 for H = 5), plus
            the refinement's candidates where a clearance term was active.
    """

    x: np.ndarray
    cost: np.ndarray
    lower_bound: np.ndarray
    exact: np.ndarray
    qp_iterations: np.ndarray
    evaluations: np.ndarray


def best_response(problems: HorizonProblems, x0: np.ndarray | None = None) -> BestResponse:
    """Solve every UAV's horizon problem exactly (see the module docstring).

    Args:
        problems: every UAV's J_i against the plans it receives, and its box
            (:func:`~uav_formation_env.policies.broadcast.horizon_problems`).
        x0: (B, N, H, 3) optional start of the active-set method (e.g. the warm starts); it only
            affects the iteration count, not the solution.

    Returns:
        :class:`BestResponse`.
    """
    cost = problems.cost
    batch, n_uav, h1 = cost.free.shape[:3]
    horizon = h1 - 1
    n = 3 * horizon
    quad = cost.quadratic(half_width=problems.half_width)
    lower, upper = box_of(problems.half_width.reshape(-1, 3), horizon)
    qp = solve_box_qp(
        2.0 * quad.hessian.reshape(-1, n, n),
        quad.linear.reshape(-1, n),
        lower,
        upper,
        None if x0 is None else np.asarray(x0, dtype=float).reshape(-1, n),
    )
    x = qp.x.copy()
    lower_bound = quad.constant.reshape(-1) + qp.value
    evaluations = np.full(batch * n_uav, identification_evaluations(horizon), dtype=np.int64)
    exact = qp.converged.copy()
    if quad.clearance_terms:
        rows = np.unique(np.concatenate([term.rows for term in quad.clearance_terms]))
        active = rows[_clearance_at(quad, x[rows], rows) > 0.0]
        if active.size:
            x[active], spent = _refine(quad.take(active), x[active], lower[active], upper[active])
            evaluations[active] += spent
            exact[active] = False
    plans = x.reshape(batch, n_uav, horizon, 3)
    return BestResponse(
        x=plans,
        cost=cost.terms(plans[:, :, None]).total[..., 0],
        lower_bound=lower_bound.reshape(batch, n_uav),
        exact=exact.reshape(batch, n_uav),
        qp_iterations=qp.iterations.reshape(batch, n_uav),
        evaluations=evaluations.reshape(batch, n_uav),
    )


def _clearance_at(quad: QuadraticCost, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The clearance terms (K,) of the problems ``rows`` (flat indices) at one point each,
    x (K, n)."""
    if x.shape[0] == 0:
        return np.zeros(0)
    grid = np.zeros((quad.constant.size, 1, x.shape[1]))
    grid[rows, 0] = x
    candidates = grid.reshape(*quad.constant.shape, 1, -1, 3)
    return quad.clearance(candidates).reshape(-1)[rows]


def _refine(
    quad: QuadraticCost, x: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, int]:
    """Sequential box-QP descent on the full J_i of problems whose clearance terms are active.

    Each step minimises the model ``J(x) + ∇J·d + dᵀQd`` over the box (the quadratic part is
    exact; the clearance terms enter through their gradient, by central differences of the one
    definition), then backtracks along the segment (inside the convex box) until Armijo's
    condition holds.

    Args:
        quad: the K problems as one copy (grid (1, K)), with their clearance terms.
        x: (K, n) start (the QP solution) inside the box.
        lower, upper: (K, n) the box.

    Returns:
        ``(x, evaluations)``: the refined points and the candidates evaluated per problem.
    """
    k, n = x.shape
    hessian = 2.0 * quad.hessian[0]
    linear = quad.linear[0]
    offsets = np.concatenate((FD_STEP * np.eye(n), -FD_STEP * np.eye(n)))

    def total(points: np.ndarray) -> np.ndarray:  # (K, P, n) -> (K, P)
        return quad.total(points.reshape(1, k, points.shape[1], -1, 3))[0]

    value = total(x[:, None])[:, 0]
    spent = 1
    for _ in range(REFINE_STEPS):
        # The quadratic part's gradient is exact from its coefficients; only the clearance
        # terms are differenced (they are C1: squared hinges).
        probe = quad.clearance((x[:, None] + offsets).reshape(1, k, 2 * n, -1, 3))[0]
        spent += 2 * n
        curvature = np.einsum("kij,kj->ki", hessian, x)
        grad = curvature + linear + (probe[:, :n] - probe[:, n:]) / (2.0 * FD_STEP)
        step = solve_box_qp(hessian, grad - curvature, lower, upper, x0=x).x - x
        slope = np.einsum("ki,ki->k", grad, step)
        moving = (slope < 0.0) & (np.abs(step).max(axis=1) > 1e-10)
        if not moving.any():  # stationary on the box (to the differencing's accuracy)
            break
        t = np.ones(k)
        for _ in range(30):
            trial = np.clip(x + t[:, None] * step, lower, upper)
            new = total(trial[:, None])[:, 0]
            spent += 1
            accept = moving & (new <= value + ARMIJO * t * slope)
            x = np.where(accept[:, None], trial, x)
            value = np.where(accept, new, value)
            moving &= ~accept
            if not moving.any():
                break
            t = np.where(moving, 0.5 * t, t)
    return x, spent
