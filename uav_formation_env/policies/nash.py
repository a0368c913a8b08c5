"""Nash gap of a plan profile and Nash equilibria of the horizon game by iterated best response.

The game at time t (docs/model.md §5, eq. 7): player i chooses its input sequence U_i in its box
``|u_n,c| <= u_max - |u_d,c|`` (docs/model.md §1.5, ``u_d = -estimate``); its cost is J_i of
:mod:`uav_formation_env.core.cost`, built from its own observation against the plans of the UAVs it
receives from (``h_ij = 1`` in its observation; every other UAV is predicted with zero inputs and
enters J_i only through the separation term). A profile ``(U_1, ..., U_N)`` is a Nash equilibrium
when no UAV can lower its J_i by changing only its own sequence.

Nash gap of a profile, per UAV: ``gap_i = J_i(U_i; U_-i) - min_{V in box_i} J_i(V; U_-i)``, where
``U_-i`` are the CURRENT plans of the profile (not shifted: they are plans for the same time t),
as receiver i sees them: its neighbours' plans, rolled out from their states as i observes them.
It is >= 0 for plans inside the box and 0 exactly at a Nash equilibrium. The minimum is the exact
best response of :mod:`uav_formation_env.policies.best_response`; where the separation term is
active at the QP solution the minimum is only bracketed (``exact = False``), see there.

Iterated best response: Jacobi (every UAV answers the profile of the previous sweep, as the
DMPC's inner rounds do) or Gauss-Seidel (UAVs answer in turn, each against the latest plans).
Both stop when every playing UAV's gap is at most ``tol · max(1, J_i)``; the gap of the returned
profile is computed, not estimated.

Shapes: B copies, N UAVs, H horizon steps.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TypeVar

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import DecodedLocalObservation
from uav_formation_env.core.observation import DecodedObservation, decode_observations
from uav_formation_env.policies.best_response import BestResponse, best_response
from uav_formation_env.policies.broadcast import HorizonProblems, horizon_problems

DecodedT = TypeVar("DecodedT", DecodedObservation, DecodedLocalObservation)

__all__ = [
    "NASH_METHODS",
    "NashConfig",
    "NashGap",
    "NashSolution",
    "iterated_best_response",
    "nash_gap",
]

NASH_METHODS = ("jacobi", "gauss_seidel")
BOX_TOL = 1e-9  # how far outside its box a plan may lie and still count as inside [m/s^2]


@dataclass(frozen=True)
class NashConfig:
    """``NashDMPCPolicy(optimizer=NashConfig(...))`` (or ``"nash"``): play the equilibrium of the
    horizon game among the triggered UAVs every step, by :func:`iterated_best_response` from the
    shifted warm starts.

    Attributes:
        method: ``"jacobi"`` or ``"gauss_seidel"``.
        max_iter: sweep cap per step.
        tol: relative gap tolerance, ``gap_i <= tol · max(1, J_i)`` [-].
    """

    method: str = "jacobi"
    max_iter: int = 200
    tol: float = 1e-12

    def __post_init__(self) -> None:
        if self.method not in NASH_METHODS:
            raise ValueError(f"method must be one of {NASH_METHODS}, got {self.method!r}")
        if not isinstance(self.max_iter, int | np.integer) or self.max_iter < 0:
            raise ValueError(f"max_iter must be an integer >= 0, got {self.max_iter!r}")
        if not (np.isfinite(self.tol) and self.tol >= 0.0):
            raise ValueError(f"tol must be finite and >= 0, got {self.tol!r}")


@dataclass(frozen=True)
class NashGap:
    """The Nash gap of a plan profile, per copy and UAV (each (B, N)).

    Attributes:
        gap: ``cost - best_cost`` [-]; >= 0 where ``in_box``.
        cost: J_i of UAV i's plan against the others' plans [-].
        best_cost: min of J_i over UAV i's box with the others' plans fixed (where not ``exact``,
            the best of the refined best response and, if in the box, the plan itself) [-].
        lower_bound: a certified lower bound of that minimum (= ``best_cost`` where exact) [-].
        exact: bool, ``best_cost`` is the exact minimum.
        in_box: bool, the plan lies in UAV i's box (within 1e-9 m/s^2).
        best_response: (B, N, H, 3) the minimising sequences [m/s^2].
    """

    gap: np.ndarray
    cost: np.ndarray
    best_cost: np.ndarray
    lower_bound: np.ndarray
    exact: np.ndarray
    in_box: np.ndarray
    best_response: np.ndarray


def nash_gap(obs: np.ndarray, scenario: Scenario, plans: np.ndarray) -> NashGap:
    """Per-UAV Nash gap of a plan profile, from what a policy-agnostic caller has.

    Args:
        obs: (B, N, dim) the observations at time t (agent order uav_0..uav_{N-1}).
        scenario: the scenario (mission data: offsets, weights, horizon, δ, u_max, schedule).
        plans: (B, N, H, 3) every UAV's input sequence for t..t+(H-1)δ [m/s^2]; e.g. a DMPC's
            broadcast plans after acting on ``obs``, or an RL action ``a · u_max`` held over the
            horizon.

    Returns:
        :class:`NashGap`. A plan outside UAV i's box can have a negative gap (``in_box`` is
        False): an RL action may use the part of ``[-u_max, u_max]`` the box leaves to the
        compensation, and the DMPC keeps a warm start that is better than the answer in a box
        that has shrunk since (its never-worse-than-W rule).
    """
    decoded = decode_observations(np.asarray(obs, dtype=float), scenario.n_uav)
    plans = _check_plans(plans, scenario, decoded.velocity.shape[:2])
    problems = horizon_problems(decoded, plans, scenario)
    return _gap(problems, plans, best_response(problems, x0=plans))


def _gap(problems: HorizonProblems, plans: np.ndarray, br: BestResponse) -> NashGap:
    cost = problems.cost.terms(plans[:, :, None]).total[..., 0]
    excess = np.abs(plans) - problems.half_width[:, :, None, :]
    in_box = (excess <= BOX_TOL).all(axis=(-2, -1))
    # An in-box plan is itself an upper bound of the minimum: this keeps the gap >= 0 against
    # rounding (exact case) and against a merely local refined answer (separation active).
    best = np.where(in_box, np.minimum(br.cost, cost), br.cost)
    return NashGap(
        gap=cost - best,
        cost=cost,
        best_cost=best,
        lower_bound=np.where(br.exact, best, br.lower_bound),
        exact=br.exact,
        in_box=in_box,
        best_response=br.x,
    )


def _check_plans(plans: np.ndarray, scenario: Scenario, batch_and_n: tuple[int, ...]) -> np.ndarray:
    plans = np.asarray(plans, dtype=float)
    expected = (*batch_and_n, scenario.cost.horizon, 3)
    if plans.shape != expected:
        raise ValueError(f"plans must have shape {expected}, got {plans.shape}")
    if not np.isfinite(plans).all():
        raise ValueError("plans contain NaN or infinite values")
    return plans


@dataclass(frozen=True)
class NashSolution:
    """Result of :func:`iterated_best_response`.

    Attributes:
        plans: (B, N, H, 3) the final profile [m/s^2].
        gap: :class:`NashGap` of ``plans`` (computed on the returned profile).
        iterations: (B,) sweeps until the copy met the tolerance (or the cap); a sweep is one
            best response of every playing UAV.
        converged: (B,) bool, every playing UAV's gap <= ``tol · max(1, J_i)``.
        max_gap_history: (S + 1, B) largest playing gap of the profile before each sweep and of
            the final profile (NaN after a copy stopped): the convergence rate.
        change: (B,) largest ``|Δu|`` of the last sweep [m/s^2].
        evaluations: (B, N) evaluations of J_i spent on best responses (identifications and
            refinements; see :class:`~uav_formation_env.policies.best_response.BestResponse`).
    """

    plans: np.ndarray
    gap: NashGap
    iterations: np.ndarray
    converged: np.ndarray
    max_gap_history: np.ndarray
    change: np.ndarray
    evaluations: np.ndarray


def iterated_best_response(
    obs: np.ndarray | DecodedObservation,
    scenario: Scenario,
    plans: np.ndarray,
    method: str = "jacobi",
    max_iter: int = 200,
    tol: float = 1e-12,
    playing: np.ndarray | None = None,
) -> NashSolution:
    """A Nash equilibrium of the horizon game at time t by iterated exact best responses.

    Args:
        obs: (B, N, dim) observations at time t, or their decoding.
        scenario: the scenario (mission data).
        plans: (B, N, H, 3) the starting profile, e.g. the shifted warm starts [m/s^2].
        method: ``"jacobi"`` (all playing UAVs answer the previous profile at once) or
            ``"gauss_seidel"`` (UAVs 0..N-1 in turn, each against the latest plans; a loop over
            UAVs, batched over copies).
        max_iter: sweep cap per copy.
        tol: stop a copy when every playing UAV's gap is <= ``tol · max(1, J_i)`` [-].
        playing: (B, N) bool, UAVs that choose their plans; the others keep ``plans`` (an
            equilibrium of the game among the players). None: every UAV.

    Returns:
        :class:`NashSolution`.
    """
    if method not in NASH_METHODS:
        raise ValueError(f"method must be one of {NASH_METHODS}, got {method!r}")
    if not isinstance(max_iter, int | np.integer) or max_iter < 0:
        raise ValueError(f"max_iter must be an integer >= 0, got {max_iter!r}")
    decoded = (
        obs
        if isinstance(obs, DecodedObservation | DecodedLocalObservation)
        else decode_observations(np.asarray(obs, dtype=float), scenario.n_uav)
    )
    batch, n_uav = decoded.velocity.shape[:2]
    plans = _check_plans(plans, scenario, (batch, n_uav)).copy()
    playing = np.ones((batch, n_uav), bool) if playing is None else np.asarray(playing, bool)
    iterations = np.zeros(batch, dtype=np.int64)
    change = np.zeros(batch)
    evaluations = np.zeros((batch, n_uav), dtype=np.int64)
    history: list[np.ndarray] = []
    running = np.arange(batch)  # copies still iterating
    final: list[tuple[np.ndarray, NashGap]] = []
    for sweep in range(max_iter + 1):
        sub = _take_copies(decoded, running)
        problems = horizon_problems(sub, plans[running], scenario)
        br = best_response(problems, x0=plans[running])
        evaluations[running] += np.where(playing[running], br.evaluations, 0)
        gap = _gap(problems, plans[running], br)
        scale = np.maximum(1.0, np.abs(gap.cost))
        worst = np.where(playing[running], gap.gap / scale, -np.inf).max(axis=1)
        row = np.full(batch, np.nan)
        row[running] = np.where(playing[running], gap.gap, -np.inf).max(axis=1)
        history.append(row)
        done = (worst <= tol) | (sweep == max_iter)
        final.append((running[done], _take_gap(gap, np.flatnonzero(done))))
        current, br_x = plans[running][~done], br.x[~done]
        running = running[~done]
        if running.size == 0:
            break
        if method == "jacobi":
            new = np.where(playing[running][..., None, None], br_x, current)
        else:
            new = _gauss_seidel_sweep(
                decoded, scenario, running, current, br_x, playing[running], evaluations
            )
        change[running] = np.abs(new - current).max(axis=(1, 2, 3))
        plans[running] = new
        iterations[running] += 1
    gap = _assemble(final, batch)
    return NashSolution(
        plans=plans,
        gap=gap,
        iterations=iterations,
        converged=_converged(gap, playing, tol),
        max_gap_history=np.stack(history),
        change=change,
        evaluations=evaluations,
    )


def _gauss_seidel_sweep(
    decoded: DecodedObservation,
    scenario: Scenario,
    copies: np.ndarray,
    plans: np.ndarray,
    first: np.ndarray,
    playing: np.ndarray,
    evaluations: np.ndarray,
) -> np.ndarray:
    """One Gauss-Seidel sweep over UAVs 0..N-1 for the given copies.

    UAV 0's answer to the current profile is ``first`` (already computed for the gap test); each
    later UAV answers the profile with the earlier UAVs' new plans.
    """
    plans = plans.copy()
    sub = _take_copies(decoded, copies)
    n_uav = plans.shape[1]
    plans[:, 0] = np.where(playing[:, 0, None, None], first[:, 0], plans[:, 0])
    for i in range(1, n_uav):
        who = np.flatnonzero(playing[:, i])
        if who.size == 0:
            continue
        problems = horizon_problems(_take_copies(sub, who), plans[who], scenario)
        # Only UAV i's problem is needed: solve row i of every copy as one batch.
        rows = np.arange(who.size) * n_uav + i
        one = HorizonProblems(
            cost=problems.cost.take(rows), half_width=problems.half_width[:, i][None]
        )
        br = best_response(one, x0=plans[who, i][None])
        plans[who, i] = br.x[0]
        evaluations[copies[who], i] += br.evaluations[0]
    return plans


def _take_copies(decoded: DecodedT, copies: np.ndarray) -> DecodedT:
    """The copies ``copies`` of decoded observations (full or local layout)."""
    taken = {f.name: getattr(decoded, f.name) for f in fields(decoded)}
    return type(decoded)(**{k: None if v is None else v[copies] for k, v in taken.items()})


def _take_gap(gap: NashGap, rows: np.ndarray) -> NashGap:
    return NashGap(**{f.name: getattr(gap, f.name)[rows] for f in fields(gap)})


def _assemble(parts: list[tuple[np.ndarray, NashGap]], batch: int) -> NashGap:
    """Scatter the per-copy gaps recorded when each copy stopped into (B, ...) arrays."""
    out = {}
    for f in fields(NashGap):
        sample = next(getattr(g, f.name) for _, g in parts)
        array = np.zeros((batch, *sample.shape[1:]), dtype=sample.dtype)
        for copies, g in parts:
            array[copies] = getattr(g, f.name)
        out[f.name] = array
    return NashGap(**out)


def _converged(gap: NashGap, playing: np.ndarray, tol: float) -> np.ndarray:
    scale = np.maximum(1.0, np.abs(gap.cost))
    return np.where(playing, gap.gap <= tol * scale, True).all(axis=1)
