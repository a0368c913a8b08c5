"""Optional compiled NFTSMO step (numba), the same arithmetic as :func:`observer.observer_step`.

The numpy loop in :mod:`uav_formation_env.core.observer` is the reference. At a batch of one its
cost is ufunc dispatch (about 25 calls per tick, 20 ticks per step), not arithmetic, so a
compiled loop over ticks and channels is ~50x faster. This kernel repeats the reference's
operations in the same order (no fast-math, no reassociation), so it gives the same numbers; a test
checks it against the reference. It is used when numba is installed (the ``[fast]`` extra) and
``UAV_FORMATION_NO_NUMBA`` is not set.
"""

from __future__ import annotations

import os

import numpy as np

from uav_formation_env.core.jit import njit_cached

try:  # pragma: no cover - exercised when the [fast] extra is installed
    if os.environ.get("UAV_FORMATION_NO_NUMBA"):
        raise ImportError("disabled by UAV_FORMATION_NO_NUMBA")
    import numba
except ImportError:  # pragma: no cover
    numba = None

AVAILABLE = numba is not None


def _step(
    v0: np.ndarray,
    accel: np.ndarray,
    u: np.ndarray,
    dt: float,
    substeps: int,
    v_hat: np.ndarray,
    s0: np.ndarray,
    d_hat: np.ndarray,
    e_prev: np.ndarray,
    gains: np.ndarray,
    literal_sign_law: bool,
    square_root_law: bool,
) -> None:
    """In place over flat (M,) arrays; gains = (pi1, lambda1, pi2, lambda2, eta, rho)."""
    pi1, lambda1, pi2, lambda2, eta, rho = (
        gains[0],
        gains[1],
        gains[2],
        gains[3],
        gains[4],
        gains[5],
    )
    h = dt / substeps
    s0_gain = h / (pi2 * lambda2)
    switch_gain = h * (eta + rho) if literal_sign_law else h * eta
    linear_gain = 0.0 if literal_sign_law else h * rho
    slope_gain = s0_gain * pi1 * lambda1
    for m in range(v0.shape[0]):
        h_u = h * u[m]
        vh, s, dh, ep = v_hat[m], s0[m], d_hat[m], e_prev[m]
        for k in range(substeps):
            v = v0[m] + (k * h) * accel[m]
            e = v - vh
            e_dot = e - ep
            e_dot /= h
            ep = e
            slope = abs(e)
            if square_root_law:
                root = np.sqrt(abs(e_dot))
                sig_l2 = e_dot * root
                sig_2ml2 = np.copysign(root, e_dot) if e_dot != 0.0 else 0.0
            else:
                slope = slope ** (lambda1 - 1.0)
                sig_l2 = abs(e_dot) ** lambda2 * np.sign(e_dot)
                sig_2ml2 = abs(e_dot) ** (2.0 - lambda2) * np.sign(e_dot)
            surface = slope * pi1
            surface += 1.0
            surface *= e
            surface += sig_l2 * pi2
            vh += h_u
            vh += h * (s + dh)
            slope *= slope_gain
            slope += s0_gain
            slope *= sig_2ml2
            s += slope
            if linear_gain:
                dh += linear_gain * surface
            dh += switch_gain * np.sign(surface)
        v_hat[m], s0[m], d_hat[m], e_prev[m] = vh, s, dh, ep


compiled_step = njit_cached(numba, _step) if AVAILABLE else None
