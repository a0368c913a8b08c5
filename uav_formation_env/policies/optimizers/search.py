"""PIO (map-and-compass, then landmark), LFPIO (numpy reference) and PSO on a population batch."""

from __future__ import annotations

import math

import numpy as np

from uav_formation_env.policies.optimizers.config import LFPIOConfig, PIOConfig, PSOConfig
from uav_formation_env.policies.optimizers.levy import (
    levy_steps_into,
)
from uav_formation_env.policies.optimizers.population import Population, weighted_centre_into


def pio_search(run: Population, rng: np.random.Generator, cfg: PIOConfig) -> None:
    x = run.initial_population(rng, cfg.n_pigeons)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    pull = np.empty_like(x)
    # Map-and-compass stage (eq. 16): decaying velocity plus a pull towards the global best.
    for it in range(1, cfg.map_compass_iters + 1):
        rand = run.rand(rng, cfg.n_pigeons, cfg.per_dimension_rand)
        np.subtract(run.best_x[:, None, :], x, out=pull)
        np.multiply(rand, pull, out=pull)
        np.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        np.add(v, pull, out=v)
        np.add(x, v, out=x)
        run.clip(x, out=x)
        cost = run.evaluate(x)
    # Landmark stage (eq. 17): keep the better half (ceil), move towards their weighted centre.
    # The survivor count is the same for every problem, so this is a per-problem sort + slice.
    alive = cfg.n_pigeons
    for _ in range(cfg.landmark_iters):
        alive = math.ceil(alive / 2)
        keep = np.argsort(cost, axis=-1, kind="stable")[:, :alive]
        rows = run.rows[:, None]
        x, cost = x[rows, keep], cost[rows, keep]
        centre = weighted_centre_into(x, cost, cfg.center_divide_by_np)[:, None, :]
        step = run.rand(rng, alive, cfg.per_dimension_rand) * (centre - x)
        x = run.clip(np.add(x, step, out=step), out=step)
        cost = run.evaluate(x)


def lfpio_search(run: Population, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    """LFPIO with preallocated contiguous buffers: the same operations, in the same order, as
    eq. 18 (so the same numbers as a plain array-expression version, bit for bit).

    Y1 overwrites X in place once ``X^c - X`` and ``X_g - X`` are formed; both candidates are
    copied into one population for a single cost call; the greedy choice copies the winning Y2
    rows over Y1 (= X_l) and takes the elementwise minimum of the two costs (``where(c2 < c1,
    c2, c1)`` and ``minimum(c1, c2)`` are the same numbers once NaN is mapped to +inf).
    """
    p = cfg.n_pigeons
    x = run.initial_population(rng, p)  # X_l, updated in place (Y1 is written over it)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    y2, to_best, to_centre, work = (np.empty_like(x) for _ in range(4))
    levy = np.empty((2, *x.shape))
    both = np.empty((run.nb, 2 * p, run.n))
    low, high = run.full_bounds(p)
    centre = weighted_centre_into(x, cost, cfg.center_divide_by_np, work)[:, None, :]
    for it in range(1, cfg.iters + 1):
        # eq. 18 with the resolutions of docs/model.md: X_{l-1} in the velocity, X^c_{l-1} in the
        # Lévy move.
        rand = run.rand(rng, p, cfg.per_dimension_rand)
        np.subtract(centre, x, out=to_centre)
        np.subtract(run.best_x[:, None, :], x, out=to_best)
        np.multiply(rand, to_best, out=to_best)
        np.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        np.add(v, to_best, out=v)
        y1 = np.add(x, v, out=x)  # Y1 = clip(X + V), written over X
        np.minimum(np.maximum(y1, low, out=y1), high, out=y1)
        s = levy_steps_into(rng, levy, cfg.levy_beta)
        np.multiply(cfg.levy_scale, s, out=s)
        np.multiply(s, to_centre, out=s)
        np.add(y1, s, out=y2)  # Y2 = clip(Y1 + r1 s ⊙ (X^c - X))
        np.minimum(np.maximum(y2, low, out=y2), high, out=y2)
        # Both candidates in one cost call (population 2P); then greedy between Y1 and Y2 only.
        np.concatenate((y1, y2), axis=1, out=both)
        both_cost = run.evaluate(both)
        cost = both_cost[:, :p]
        take_y2 = both_cost[:, p:] < cost
        np.copyto(x, y2, where=take_y2[..., None])
        np.minimum(cost, both_cost[:, p:], out=cost)
        centre = weighted_centre_into(x, cost, cfg.center_divide_by_np, work)[:, None, :]


def pso_search(run: Population, rng: np.random.Generator, cfg: PSOConfig) -> None:
    p = cfg.n_particles
    x = run.initial_population(rng, p)
    cost = run.evaluate(x)
    v = np.zeros_like(x)
    own_x, own_cost = x.copy(), cost
    for _ in range(cfg.resolved_iters):
        r1 = run.rand(rng, p, cfg.per_dimension_rand)
        r2 = run.rand(rng, p, cfg.per_dimension_rand)
        v = (
            cfg.inertia * v
            + cfg.cognitive * r1 * (own_x - x)
            + cfg.social * r2 * (run.best_x[:, None, :] - x)
        )
        x = run.clip(x + v)
        cost = run.evaluate(x)
        improved = cost < own_cost
        np.copyto(own_x, x, where=improved[..., None])
        own_cost = np.where(improved, cost, own_cost)
