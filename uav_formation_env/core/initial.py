"""Initial UAV positions: uniform in a box, at least a minimum spacing apart."""

from __future__ import annotations

import numpy as np

MAX_REDRAWS = 1000  # rounds of redrawing the UAVs that are too close before giving up


def too_close(positions: np.ndarray, min_spacing: float) -> np.ndarray:
    """(N,) bool: UAV i is closer than ``min_spacing`` to some UAV j < i.

    Marking only the later UAV of each close pair lets the earlier one stay where it is.

    Args:
        positions: (N, 3) [m].
        min_spacing: [m].
    """
    diff = positions[:, None, :] - positions[None, :, :]
    close = np.einsum("ijk,ijk->ij", diff, diff) < min_spacing**2
    return np.tril(close, k=-1).any(axis=1)


def initial_positions(
    rng: np.random.Generator,
    n_uav: int,
    low: np.ndarray,
    high: np.ndarray,
    min_spacing: float,
) -> np.ndarray:
    """Positions uniform in the box ``[low, high]`` with every pair ``min_spacing`` apart.

    The first draw is ``low + (high - low) * rng.random((N, 3))``; while some UAVs are closer
    than ``min_spacing`` to an earlier one, those alone are redrawn. All draws come from ``rng``
    (the copy's own generator), so the layout depends on the copy's seed only.

    Args:
        rng: the copy's generator.
        n_uav: N.
        low, high: (3,) corners of the box [m].
        min_spacing: [m]; 0 accepts the first draw.

    Returns:
        (N, 3) [m].

    Raises:
        ValueError: if no layout was found after :data:`MAX_REDRAWS` rounds (the box is too
            small for N UAVs at that spacing).
    """
    positions = low + (high - low) * rng.random((n_uav, 3))
    if min_spacing <= 0:
        return positions
    for _ in range(MAX_REDRAWS):
        redraw = too_close(positions, min_spacing)
        count = int(redraw.sum())
        if count == 0:
            return positions
        positions[redraw] = low + (high - low) * rng.random((count, 3))
    raise ValueError(
        f"initial.min_spacing: could not place {n_uav} UAVs {min_spacing} m apart in the box "
        f"{tuple(low)}..{tuple(high)} after {MAX_REDRAWS} redraws; enlarge the box or lower "
        "min_spacing"
    )


def formation_positions(
    rng: np.random.Generator, slots: np.ndarray, centre: np.ndarray, jitter: float
) -> np.ndarray:
    """A start in formation: each UAV at its slot about ``centre``, moved horizontally by
    U(-jitter, jitter) per axis (drawn from the copy's generator).

    Args:
        rng: the copy's generator.
        slots: (N, 3) formation slot positions relative to the formation's reference [m].
        centre: (3,) where the slots' mean goes [m].
        jitter: [m].

    Returns:
        (N, 3) [m].
    """
    positions = centre + slots - slots.mean(axis=0)
    positions[:, :2] += rng.uniform(-jitter, jitter, size=(len(slots), 2))
    return positions
