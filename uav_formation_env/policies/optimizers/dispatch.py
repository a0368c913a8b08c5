"""``minimise``: one entry point for every optimiser (PIO, LFPIO numpy or compiled, PSO)."""

from __future__ import annotations

import numpy as np

from uav_formation_env.policies.optimizers.config import (
    CostFn,
    LFPIOConfig,
    OptimConfig,
    OptimResult,
    PIOConfig,
    PSOConfig,
)
from uav_formation_env.policies.optimizers.lfpio_kernels import (
    COMPILED_AVAILABLE,
    lfpio_search_compiled,
)
from uav_formation_env.policies.optimizers.population import Population
from uav_formation_env.policies.optimizers.search import lfpio_search, pio_search, pso_search
from uav_formation_env.policies.optimizers.streams import CounterStreams, RandomSource, RowStreams


def minimise(
    cost_fn: CostFn,
    x0: np.ndarray,
    low: np.ndarray | float,
    high: np.ndarray | float,
    rng: RandomSource,
    config: OptimConfig,
    *,
    batch_ndim: int = 1,
    compiled: bool | None = None,
) -> OptimResult:
    """Minimise a vectorised cost over a box for a batch of independent problems.

    Args:
        cost_fn: Maps positions ``(*batch, P, *dims)`` to costs ``(*batch, P)``, assumed ``>= 0``.
            Called once per evaluation batch on the whole population; ``P`` varies between calls
            (PIO's landmark stage shrinks it, LFPIO evaluates ``2 Np`` candidates at once). It
            must not modify its argument, and must copy it to keep it: the array may be a
            buffer that later iterations overwrite.
        x0: ``(*batch, *dims)`` warm start; it is pigeon 0 and the initial global best.
        low: Lower bounds, broadcastable to ``(*batch, *dims)``, finite.
        high: Upper bounds, broadcastable to ``(*batch, *dims)``, finite, ``>= low``.
        rng: The only source of randomness: a generator,
            :class:`~uav_formation_env.policies.optimizers.streams.RowStreams` (each problem's
            draws from its own copy's generator) or
            :class:`~uav_formation_env.policies.optimizers.streams.CounterStreams` (counter-based
            draws on the device of its keys, which must be that of ``x0``).
        config: :class:`PIOConfig`, :class:`LFPIOConfig` or :class:`PSOConfig`.
        batch_ndim: How many leading axes of ``x0`` are batch axes (1 for ``(M, H, 3)``).
        compiled: Run LFPIO's per-iteration bookkeeping as compiled numba kernels (the same
            numbers as the numpy code, ~2x faster at small batches). None: whenever numba is
            installed (the ``[fast]`` extra), ``UAV_FORMATION_NO_NUMBA`` is unset and ``x0`` is
            a numpy array. Only LFPIO with ``prod(dims) >= 2`` on numpy has kernels; other
            cases run the array code (numpy, or torch for a tensor ``x0``: the populations stay
            on its device, the random draws come from ``rng`` on the host).

    Returns:
        The best position evaluated per problem, never worse than ``x0``; see :class:`OptimResult`.

    Raises:
        TypeError: If ``rng`` is not a ``numpy.random.Generator`` or ``config`` is unknown.
        ValueError: On bad bounds, ``batch_ndim`` or a cost of the wrong shape.
    """
    if not isinstance(rng, np.random.Generator | RowStreams | CounterStreams):
        raise TypeError(
            "rng must be a numpy.random.Generator, RowStreams or CounterStreams, got "
            f"{type(rng).__name__}"
        )
    run = Population(cost_fn, x0, low, high, batch_ndim)
    if isinstance(config, PIOConfig):
        pio_search(run, rng, config)
    elif isinstance(config, LFPIOConfig):
        on_numpy = isinstance(run.x0, np.ndarray)
        if compiled is None:
            compiled = COMPILED_AVAILABLE and on_numpy
        if compiled and not COMPILED_AVAILABLE:
            raise RuntimeError("compiled=True needs numba (the [fast] extra)")
        if compiled and not on_numpy:
            raise ValueError("compiled=True runs on numpy arrays only; x0 is a tensor")
        if compiled and run.n >= 2:
            lfpio_search_compiled(run, rng, config)
        else:
            lfpio_search(run, rng, config)
    elif isinstance(config, PSOConfig):
        pso_search(run, rng, config)
    else:
        raise TypeError(f"unknown optimiser config {type(config).__name__}")
    return run.result()
