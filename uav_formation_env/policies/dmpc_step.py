"""One control step of the DMPC: the solvers of its horizon problems, and what a step records.

Solvers work at two levels (docs/model.md §5, §6):

- a :class:`BestResponseSolver` answers M horizon problems, each UAV's J_i against fixed
  neighbour plans, from warm starts inside their boxes: :class:`MetaheuristicSolver` (PIO, LFPIO,
  PSO through :func:`~uav_formation_env.policies.optimizers.minimise`) or :class:`ExactSolver`
  (:func:`~uav_formation_env.policies.best_response.best_response`);
- a :class:`StepSolver` plays a whole control step of every UAV of every copy, from the decoded
  observations and the last broadcast plans: :class:`TriggeredRounds` (warm start, event trigger,
  a best response of each triggered UAV, never worse than W; K rounds, the paper's scheme with
  K = 1) or :class:`NashIteration` (warm start, event trigger, iterated exact best responses among
  the triggered UAVs to an equilibrium of their horizon game).

:func:`step_solver` builds the step solver of a solver config. Each step gives the output plans and
a :class:`StepRecord`; :meth:`DMPCRecords.from_steps` stacks the records of an episode.

Shapes: B copies, N UAVs, H horizon steps, M flattened (triggered) problems.

:class:`TriggeredRounds` with a :class:`MetaheuristicSolver` runs on numpy or torch (the library
and device of the decoded observations and plans); the exact solvers and :class:`NashIteration`
run on numpy. Records are numpy arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.array_api import asarray_like, copy, device, namespace_of, to_numpy
from uav_formation_env.core.observation import DecodedObservation
from uav_formation_env.policies.best_response import ExactConfig, best_response
from uav_formation_env.policies.broadcast import (
    HorizonProblems,
    horizon_problems,
    observed_time,
    shift_warm_start,
)
from uav_formation_env.policies.nash import NashConfig, iterated_best_response
from uav_formation_env.policies.optimizers import (
    CounterStreams,
    OptimConfig,
    RowStreams,
    minimise,
)
from uav_formation_env.policies.solvers import SolverConfig

__all__ = [
    "DRAWS_PER_ROUND",
    "BestResponseSolver",
    "CounterKeys",
    "DMPCRecords",
    "ExactSolver",
    "MetaheuristicSolver",
    "NashIteration",
    "StepRecord",
    "StepSolver",
    "TriggeredRounds",
    "step_solver",
]


# counter draw indices reserved per inner round: a solve makes 1 + 2 x iterations draws (61 for
# LFPIO), so any practical iteration budget fits, and 4,096 rounds fit the 32-bit draw word
DRAWS_PER_ROUND = 2**20


@dataclass(frozen=True)
class CounterKeys:
    """Counter-based randomness for a step: each copy's Philox key.

    The triggered problem of UAV i in copy b at control step k draws with key ``keys[b]`` and
    counter words (element, draw, i, k) (:class:`~uav_formation_env.policies.optimizers.
    CounterStreams`), so its numbers depend on nothing else (not on the batch, nor on which
    other UAVs trigger), and numpy and torch draw the same numbers.

    Attributes:
        keys: (B, 2) int64 key words in [0, 2^32).
    """

    keys: np.ndarray


@dataclass(frozen=True)
class StepRecord:
    """What one control step did (leading dims: B copies, N UAVs); see :class:`DMPCRecords`."""

    time: np.ndarray  # (B,)
    triggered: np.ndarray  # (B, N) bool
    j_pre: np.ndarray  # (B, N)
    j_exec: np.ndarray  # (B, N)
    evaluations: np.ndarray  # (B, N) int
    nash_iterations: np.ndarray  # (B,) int
    nash_converged: np.ndarray  # (B,) bool

    @classmethod
    def of(
        cls,
        decoded: DecodedObservation,
        scenario: Scenario,
        triggered: np.ndarray,
        j_pre: np.ndarray,
        j_exec: np.ndarray,
        evaluations: np.ndarray,
        nash_iterations: np.ndarray | None = None,
        nash_converged: np.ndarray | None = None,
    ) -> StepRecord:
        """The record of the step at the observed time (no Nash sweeps: 0 and converged), as
        numpy arrays whatever the backend of its inputs."""
        batch = triggered.shape[0]
        return cls(
            time=to_numpy(
                observed_time(decoded.time_fraction[:, 0], scenario.duration, scenario.dynamics.dt)
            ),
            triggered=to_numpy(triggered),
            j_pre=to_numpy(j_pre),
            j_exec=to_numpy(j_exec),
            evaluations=to_numpy(evaluations),
            nash_iterations=(
                np.zeros(batch, dtype=np.int64) if nash_iterations is None else nash_iterations
            ),
            nash_converged=(
                np.ones(batch, dtype=bool) if nash_converged is None else nash_converged
            ),
        )


@dataclass(frozen=True)
class DMPCRecords:
    """Per-step records of T steps, B copies and N UAVs.

    Attributes:
        time: (T, B) time t of the step [s].
        triggered: (T, B, N) bool, ``J_pre > threshold`` (in any inner round).
        j_pre: (T, B, N) J_i of the warm start W_i against the neighbours' warm starts [-].
        j_exec: (T, B, N) J_i of the output sequence (against the last round's plans) [-].
        evaluations: (T, B, N) the optimiser's cost evaluations (its budget: 1830 for LFPIO,
            810 for PIO; 0 when not triggered). With ``population_cost="quadratic"`` these are
            quadratic-form evaluations; identifying the form costs 1 + 2n + n(n-1)/2 = 136 (H = 5)
            direct evaluations of J_i per triggered UAV, not counted here. For ``"exact"`` and
            ``"nash"`` they are exactly those identification evaluations (136 per best response;
            plus the refinement's candidates where the separation term is active), summed over
            the best responses the UAV computed (``"nash"``: one per sweep, plus the final gap
            check); the solve itself evaluates nothing.
        wall_time: (T,) wall-clock time of the whole step, all copies and UAVs [s].
        nash_iterations: (T, B) sweeps of iterated best response (``"nash"``; 0 for the other
            optimisers and for copies where no UAV was triggered).
        nash_converged: (T, B) bool, the ``"nash"`` profile met its gap tolerance (True for the
            other optimisers).
    """

    time: np.ndarray
    triggered: np.ndarray
    j_pre: np.ndarray
    j_exec: np.ndarray
    evaluations: np.ndarray
    wall_time: np.ndarray
    nash_iterations: np.ndarray | None = None
    nash_converged: np.ndarray | None = None

    @classmethod
    def from_steps(
        cls, steps: Sequence[StepRecord], wall_time: Sequence[float], batch: int, n_uav: int
    ) -> DMPCRecords:
        """The step records stacked along a leading time axis (empty arrays for no step)."""
        if not steps:
            empty = np.zeros((0, batch, n_uav))
            return cls(
                time=np.zeros((0, batch)),
                triggered=empty.astype(bool),
                j_pre=empty,
                j_exec=empty.copy(),
                evaluations=empty.astype(np.int64),
                wall_time=np.zeros(0),
                nash_iterations=np.zeros((0, batch), dtype=np.int64),
                nash_converged=np.zeros((0, batch), dtype=bool),
            )
        stacked = {
            f.name: np.stack([getattr(s, f.name) for s in steps]) for f in fields(StepRecord)
        }
        return cls(wall_time=np.asarray(wall_time), **stacked)


# ---------------------------------------------------------------------------------- per problem
class BestResponseSolver(Protocol):
    """Answers M horizon problems, each against fixed neighbour plans."""

    def solve(
        self, problems: HorizonProblems, x0: np.ndarray, streams: RowStreams
    ) -> tuple[np.ndarray, np.ndarray | int]:
        """Args: ``problems`` the M problems as one copy (grid (1, M), half widths (1, M, 3));
        ``x0`` (M, H, 3) the warm starts; ``streams`` the random rows of the M problems.

        Returns: ``(x (M, H, 3) inside the boxes, cost evaluations per problem)``."""
        ...


@dataclass(frozen=True)
class MetaheuristicSolver:
    """PIO / LFPIO / PSO from the warm start (pigeon 0) over the box.

    Attributes:
        config: the optimiser's config.
        population_cost: ``"quadratic"`` (J_i's identified quadratic form plus the separation
            term of the pairs that can be active in the box) or ``"direct"`` (the full formula).
    """

    config: OptimConfig
    population_cost: str = "quadratic"

    def solve(
        self, problems: HorizonProblems, x0: np.ndarray, streams: RowStreams
    ) -> tuple[np.ndarray, int]:
        cost, half = problems.cost, problems.half_width[0][:, None, :]  # (M, 1, 3)
        if self.population_cost == "quadratic":
            population_cost = cost.quadratic(half_width=problems.half_width).total
        else:
            population_cost = cost.terms_total
        result = minimise(
            lambda x, f=population_cost: f(x[None])[0], x0, -half, half, streams, self.config
        )
        return result.x, result.n_evals


class ExactSolver:
    """The exact minimiser over the box; it draws nothing from the streams."""

    def solve(
        self, problems: HorizonProblems, x0: np.ndarray, streams: RowStreams
    ) -> tuple[np.ndarray, np.ndarray]:
        exact = best_response(problems, x0=x0[None])
        return exact.x[0], exact.evaluations[0]


# ------------------------------------------------------------------------------------ per step
class StepSolver(Protocol):
    """Plays one control step of every UAV of every copy."""

    def step(
        self,
        decoded: DecodedObservation,
        plans: np.ndarray,
        threshold: float,
        rngs: Sequence[np.random.Generator] | CounterKeys,
    ) -> tuple[np.ndarray, StepRecord]:
        """Args: ``decoded`` the observations (B, N, dim) decoded; ``plans`` (B, N, H, 3) the
        plans broadcast at the last step; ``threshold`` the event trigger on J_i(W); ``rngs``
        one generator per copy.

        Returns: ``(output plans (B, N, H, 3), the step's record)``."""
        ...


@dataclass(frozen=True)
class TriggeredRounds:
    """Warm start, trigger and a batched best response of the triggered UAVs, K rounds.

    Every round re-builds the problems against the neighbours' outputs of the previous round
    (round 0: the shifted warm starts), triggers on J_i of the current sequence, and keeps the
    solver's answer only where its exact J_i is strictly lower (never worse than W).
    """

    scenario: Scenario
    solver: BestResponseSolver
    inner_rounds: int = 1

    def step(
        self,
        decoded: DecodedObservation,
        plans: np.ndarray,
        threshold: float,
        rngs: Sequence[np.random.Generator] | CounterKeys,
    ) -> tuple[np.ndarray, StepRecord]:
        h = self.scenario.cost.horizon
        current = shift_warm_start(plans)  # W_i, and W_j as the receivers compute it
        xp, on = namespace_of(current), device(current)
        shape = tuple(current.shape[:2])
        triggered = xp.zeros(shape, dtype=xp.bool, device=on)
        evals = xp.zeros(shape, dtype=xp.int64, device=on)
        j_pre = j_cur = xp.zeros(shape, dtype=current.dtype, device=on)
        for round_ in range(self.inner_rounds):
            problems = horizon_problems(decoded, current, self.scenario)
            j_cur = problems.cost.terms(current[:, :, None]).total[..., 0]
            if round_ == 0:
                j_pre = j_cur
            trig = j_cur > threshold
            triggered |= trig
            index = xp.nonzero(xp.reshape(trig, (-1,)))[0]
            if index.shape[0] == 0:
                continue
            sub = problems.cost.take(index)  # the M triggered problems as one copy
            half = problems.half_width.reshape(-1, 3)[index][None]  # (1, M, 3)
            x0 = current.reshape(-1, h, 3)[index]
            streams = self._streams(decoded, rngs, trig, index, round_)
            result_x, n_evals = self.solver.solve(HorizonProblems(sub, half), x0, streams)
            # Exact J_i of the solver's answer; keep W where it is not strictly better.
            found = sub.terms(result_x[None, :, None]).total[0, :, 0]
            better = found < xp.reshape(j_cur, (-1,))[index]
            flat = copy(xp.reshape(current, (-1, h, 3)))
            flat[index[better]] = result_x[better]
            current = xp.reshape(flat, current.shape)
            j_cur = copy(j_cur)
            xp.reshape(j_cur, (-1,))[index[better]] = found[better]
            xp.reshape(evals, (-1,))[index] += n_evals
        return current, StepRecord.of(decoded, self.scenario, triggered, j_pre, j_cur, evals)

    def _streams(
        self,
        decoded: DecodedObservation,
        rngs: Sequence[np.random.Generator] | CounterKeys,
        trig: np.ndarray,
        index: np.ndarray,
        round_: int,
    ) -> RowStreams | CounterStreams:
        """The random source of the triggered problems ``index`` (flat, ordered by copy)."""
        xp = namespace_of(index)
        if not isinstance(rngs, CounterKeys):  # the row counts go to the host generators
            return RowStreams(rngs, to_numpy(xp.sum(trig, axis=1)))
        n_uav = trig.shape[1]
        dt = self.scenario.dynamics.dt
        now = observed_time(decoded.time_fraction[:, 0], self.scenario.duration, dt)
        step = xp.astype(xp.round(now / dt), index.dtype)  # (B,) the control step k
        copy_of, uav = index // n_uav, index % n_uav
        keys = asarray_like(rngs.keys, index)[copy_of]
        labels = xp.stack((uav, step[copy_of]), axis=1)
        return CounterStreams(keys, labels, first_draw=round_ * DRAWS_PER_ROUND)


@dataclass(frozen=True)
class NashIteration:
    """Warm start, trigger, and an equilibrium among the triggered UAVs of every copy.

    The triggered UAVs iterate exact best responses from the warm starts (the untriggered keep
    W_i and are not players) until every player's Nash gap is within the tolerance; ``j_exec`` is
    J_i of the output against the output profile.
    """

    scenario: Scenario
    config: NashConfig

    def step(
        self,
        decoded: DecodedObservation,
        plans: np.ndarray,
        threshold: float,
        rngs: Sequence[np.random.Generator] | CounterKeys,
    ) -> tuple[np.ndarray, StepRecord]:
        warm = shift_warm_start(plans)
        problems = horizon_problems(decoded, warm, self.scenario)
        j_pre = problems.cost.terms(warm[:, :, None]).total[..., 0]
        triggered = j_pre > threshold
        if not triggered.any():
            evals = np.zeros(triggered.shape, dtype=np.int64)
            return warm, StepRecord.of(decoded, self.scenario, triggered, j_pre, j_pre, evals)
        solution = iterated_best_response(
            decoded,
            self.scenario,
            warm,
            method=self.config.method,
            max_iter=self.config.max_iter,
            tol=self.config.tol,
            playing=triggered,
        )
        # A copy with no player stopped at sweep 0 with its warm starts and their costs.
        return solution.plans, StepRecord.of(
            decoded,
            self.scenario,
            triggered,
            j_pre,
            solution.gap.cost,
            solution.evaluations,
            solution.iterations,
            solution.converged,
        )


def step_solver(
    config: SolverConfig,
    scenario: Scenario,
    inner_rounds: int = 1,
    population_cost: str = "quadratic",
) -> StepSolver:
    """The step solver of a solver config (``inner_rounds`` must be 1 for :class:`NashConfig`)."""
    if isinstance(config, NashConfig):
        if inner_rounds != 1:
            raise ValueError("inner_rounds must be 1 with the 'nash' optimizer")
        return NashIteration(scenario, config)
    if isinstance(config, ExactConfig):
        solver: BestResponseSolver = ExactSolver()
    else:
        solver = MetaheuristicSolver(config, population_cost)
    return TriggeredRounds(scenario, solver, inner_rounds)
