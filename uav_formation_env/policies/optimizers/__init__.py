"""Batched derivative-free minimisers: PIO, LFPIO (docs/model.md §6) and a PSO baseline.

The optimisers know nothing about UAVs. They minimise a vectorised cost over a box, for a batch of
independent problems at once, in the evosax / pymoo style: the whole population of every problem
is evaluated in one call, the update rules are array operations, and all randomness comes from the
``numpy.random.Generator`` handed in (same seed, bit-identical result).

Shapes: a problem is a point of shape ``dims`` (``(H, 3)`` for a UAV's input sequence); a call
solves ``batch`` problems (``(M,)`` for M UAVs), so ``x0`` has shape ``(*batch, *dims)`` and the
cost is called on populations ``(*batch, P, *dims)`` returning ``(*batch, P)``. Internally ``dims``
is flattened to ``n`` components.

Conventions shared by all three methods (docs/model.md §6):

- Costs are assumed to be ``J >= 0`` (the paper's performance index is a sum of squares). Fitness
  is ``f = 1 / (max(J, 0) + 1e-12)``; it only weights the LFPIO/PIO centre and orders the PIO
  landmark survivors. NaN costs are treated as ``+inf`` (fitness 0, never selected as best).
- Pigeon/particle 0 is the warm start ``x0`` (clipped into the box, a no-op for a feasible warm
  start); the others are uniform in the box; initial velocities are 0.
- Positions are clipped to ``[low, high]`` after every move; velocities are kept as they are.
- The best position ever evaluated is updated after every evaluation batch and returned, so the
  result is never worse than ``x0`` and ``cost_fn(result.x)`` reproduces ``result.cost``.
- ``rand`` is one U[0, 1) scalar per pigeon per iteration, or one per component with
  ``per_dimension_rand``.

Speed: at the DMPC's sizes (a few problems of 30 pigeons x 15 components) an iteration is
dominated by per-call overhead, so the loops work in preallocated buffers. LFPIO's bookkeeping
also exists as numba kernels giving the same numbers bit for bit (tested), used when numba is
installed (the ``[fast]`` extra) unless ``UAV_FORMATION_NO_NUMBA`` is set.
"""

__all__ = [
    "COMPILED_AVAILABLE",
    "CounterStreams",
    "FITNESS_EPS",
    "OPTIMIZERS",
    "LFPIOConfig",
    "OptimConfig",
    "OptimResult",
    "PIOConfig",
    "PSOConfig",
    "RowStreams",
    "fitness",
    "levy_steps",
    "mantegna_components",
    "mantegna_sigma",
    "minimise",
    "n_evaluations",
    "weighted_centre",
]


from uav_formation_env.policies.optimizers.config import (
    FITNESS_EPS,
    OPTIMIZERS,
    LFPIOConfig,
    OptimConfig,
    OptimResult,
    PIOConfig,
    PSOConfig,
    n_evaluations,
)
from uav_formation_env.policies.optimizers.dispatch import minimise
from uav_formation_env.policies.optimizers.levy import (
    levy_steps,
    mantegna_components,
    mantegna_sigma,
)
from uav_formation_env.policies.optimizers.lfpio_kernels import COMPILED_AVAILABLE
from uav_formation_env.policies.optimizers.population import fitness, weighted_centre
from uav_formation_env.policies.optimizers.streams import CounterStreams, RowStreams
