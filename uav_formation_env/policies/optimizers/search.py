"""PIO (map-and-compass, then landmark), LFPIO (the reference form) and PSO on a population batch.

Backend-neutral (numpy, or torch on any device: the library of the :class:`Population`); the
random numbers are drawn on the host from the numpy generators and moved to the device.
"""

from __future__ import annotations

import math

import numpy as np

from uav_formation_env.core.array_api import concat_into, copy, copy_where, device, namespace_of
from uav_formation_env.policies.optimizers.config import LFPIOConfig, PIOConfig, PSOConfig
from uav_formation_env.policies.optimizers.levy import (
    levy_steps_into,
)
from uav_formation_env.policies.optimizers.population import Population, weighted_centre_into
from uav_formation_env.policies.optimizers.streams import CounterStreams


def pio_search(run: Population, rng: np.random.Generator, cfg: PIOConfig) -> None:
    xp = run.xp
    x = run.initial_population(rng, cfg.n_pigeons)
    cost = run.evaluate(x)
    v = xp.zeros_like(x)
    pull = xp.empty_like(x)
    # Map-and-compass stage (eq. 16): decaying velocity plus a pull towards the global best.
    for it in range(1, cfg.map_compass_iters + 1):
        rand = run.rand(rng, cfg.n_pigeons, cfg.per_dimension_rand)
        xp.subtract(run.best_x[:, None, :], x, out=pull)
        xp.multiply(rand, pull, out=pull)
        xp.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        xp.add(v, pull, out=v)
        xp.add(x, v, out=x)
        run.clip(x, out=x)
        cost = run.evaluate(x)
    # Landmark stage (eq. 17): keep the better half (ceil), move towards their weighted centre.
    # The survivor count is the same for every problem, so this is a per-problem sort + slice.
    alive = cfg.n_pigeons
    for _ in range(cfg.landmark_iters):
        alive = math.ceil(alive / 2)
        keep = xp.argsort(cost, axis=-1, stable=True)[:, :alive]
        rows = run.rows[:, None]
        x, cost = x[rows, keep], cost[rows, keep]
        centre = weighted_centre_into(x, cost, cfg.center_divide_by_np)[:, None, :]
        step = run.rand(rng, alive, cfg.per_dimension_rand) * (centre - x)
        x = run.clip(xp.add(x, step, out=step), out=step)
        cost = run.evaluate(x)


def lfpio_search(run: Population, rng: np.random.Generator, cfg: LFPIOConfig) -> None:
    """LFPIO with preallocated contiguous buffers: the same operations, in the same order, as
    eq. 18 (so the same numbers as a plain array-expression version, bit for bit).

    Y1 overwrites X in place once ``X^c - X`` and ``X_g - X`` are formed; both candidates are
    copied into one population for a single cost call; the greedy choice copies the winning Y2
    rows over Y1 (= X_l) and takes the elementwise minimum of the two costs (``where(c2 < c1,
    c2, c1)`` and ``minimum(c1, c2)`` are the same numbers once NaN is mapped to +inf).
    """
    xp, p = run.xp, cfg.n_pigeons
    x = run.initial_population(rng, p)  # X_l, updated in place (Y1 is written over it)
    cost = run.evaluate(x)
    v = xp.zeros_like(x)
    y2, to_best, to_centre, work = (xp.empty_like(x) for _ in range(4))
    if isinstance(rng, CounterStreams):  # the Lévy draws: where the generator draws them
        levy = xp.empty((2, *x.shape), dtype=x.dtype, device=device(x))
    else:
        levy = np.empty((2, *x.shape))
    both = xp.empty((run.nb, 2 * p, run.n), dtype=x.dtype, device=device(x))
    low, high = run.full_bounds(p)
    centre = weighted_centre_into(x, cost, cfg.center_divide_by_np, work)[:, None, :]
    for it in range(1, cfg.iters + 1):
        # eq. 18 with the resolutions of docs/model.md: X_{l-1} in the velocity, X^c_{l-1} in the
        # Lévy move.
        rand = run.rand(rng, p, cfg.per_dimension_rand)
        xp.subtract(centre, x, out=to_centre)
        xp.subtract(run.best_x[:, None, :], x, out=to_best)
        xp.multiply(rand, to_best, out=to_best)
        xp.multiply(v, math.exp(-cfg.map_compass_factor * it), out=v)
        xp.add(v, to_best, out=v)
        y1 = xp.add(x, v, out=x)  # Y1 = clip(X + V), written over X
        xp.minimum(xp.maximum(y1, low, out=y1), high, out=y1)
        drawn = levy_steps_into(rng, levy, cfg.levy_beta)
        namespace_of(drawn).multiply(cfg.levy_scale, drawn, out=drawn)
        s = run.on_device(drawn)
        xp.multiply(s, to_centre, out=s)
        xp.add(y1, s, out=y2)  # Y2 = clip(Y1 + r1 s ⊙ (X^c - X))
        xp.minimum(xp.maximum(y2, low, out=y2), high, out=y2)
        # Both candidates in one cost call (population 2P); then greedy between Y1 and Y2 only.
        concat_into(both, (y1, y2), axis=1)
        both_cost = run.evaluate(both)
        cost = both_cost[:, :p]
        take_y2 = both_cost[:, p:] < cost
        copy_where(x, y2, take_y2[..., None])
        xp.minimum(cost, both_cost[:, p:], out=cost)
        centre = weighted_centre_into(x, cost, cfg.center_divide_by_np, work)[:, None, :]


def pso_search(run: Population, rng: np.random.Generator, cfg: PSOConfig) -> None:
    xp, p = run.xp, cfg.n_particles
    x = run.initial_population(rng, p)
    cost = run.evaluate(x)
    v = xp.zeros_like(x)
    own_x, own_cost = copy(x), cost
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
        copy_where(own_x, x, improved[..., None])
        own_cost = xp.where(improved, cost, own_cost)
