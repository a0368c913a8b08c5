"""Seeds and per-copy random streams, shared by the simulator and the stochastic policies.

A seed names an episode: copy b of a batch draws only from its own generator, seeded from its
episode's seed, so seed s flies the same alone and inside any batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["check_seed", "copy_streams"]


def check_seed(seed: object, name: str = "seed") -> int | None:
    """``seed`` as an int, or None; anything but None or a non-negative integer is an error.

    Raises:
        TypeError: for a float, string, bool or other non-integer (``1.7`` is not seed 1).
        ValueError: for a negative integer.
    """
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise TypeError(f"{name} must be None or a non-negative int, got {seed!r}")
    if seed < 0:
        raise ValueError(f"{name} must be None or a non-negative int, got {seed!r}")
    return int(seed)


def copy_streams(
    batch_size: int, root: int | None, seeds: Sequence[int | None] | None = None
) -> list[np.random.Generator]:
    """One generator per copy.

    Args:
        batch_size: B.
        root: a policy's own seed (None: none).
        seeds: the episode seed of each copy, or None. Copy b's generator is seeded with
            ``(seeds[b], root)`` (``seeds[b]`` alone if root is None); a copy whose seed is None,
            or every copy when ``seeds`` is None, gets child b of ``SeedSequence(root)`` (fresh
            entropy if root is None too).

    Returns:
        B independent generators.
    """
    spawned = np.random.SeedSequence(root).spawn(batch_size)
    if seeds is None:
        seeds = [None] * batch_size
    return [
        np.random.default_rng(child if s is None else [s] if root is None else [s, root])
        for s, child in zip(seeds, spawned)
    ]
