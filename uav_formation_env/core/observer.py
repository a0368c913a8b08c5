"""Non-singular fast terminal sliding-mode disturbance observer, NFTSMO (docs/model.md §3).

The 6-dimensional observer of eq. 10 splits into independent scalar channels; the position channels
carry no disturbance, so three scalar observers run on the velocity, ``e = v - v_hat``. Per inner
tick of length ``h`` (finite-difference form, docs/model.md §3.3), elementwise:

    e = v - v_hat;   e' = (e - e_prev) / h
    s = e + Π1 sig^λ1(e) + Π2 sig^λ2(e')
    v_hat += h (u + s0 + d_hat)
    s0    += h (1 + Π1 λ1 |e|^(λ1-1)) sig^(2-λ2)(e') / (Π2 λ2)
    d_hat += h (η sign(s) + ρ s)            [literal option: (η + ρ) sign(s)]

``sig^a(x) = |x|^a sign(x)``. The disturbance estimate is the total injection ``d_hat + s0``
(``estimate_without_s0`` uses ``d_hat`` alone) and the compensation is ``u_d = -estimate``
(docs/model.md §3.4: the paper's ``+B⁺ d_hat`` doubles the disturbance).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from uav_formation_env.config import ObserverConfig
from uav_formation_env.core import observer_kernel


@dataclass
class ObserverState:
    """Observer state, every array (..., 3): v_hat [m/s], s0 and d_hat [m/s^2], e_prev [m/s]."""

    v_hat: np.ndarray
    s0: np.ndarray
    d_hat: np.ndarray
    e_prev: np.ndarray

    def copy(self) -> ObserverState:
        return ObserverState(
            self.v_hat.copy(), self.s0.copy(), self.d_hat.copy(), self.e_prev.copy()
        )


def observer_init(v: np.ndarray) -> ObserverState:
    """Initial state: ``v_hat = v(0)``, zero estimates and zero previous error.

    Args:
        v: (..., 3) measured velocity [m/s].
    """
    zeros = np.zeros_like(v, dtype=float)
    return ObserverState(np.array(v, dtype=float), zeros.copy(), zeros.copy(), zeros.copy())


def _sig(x: np.ndarray, power: float) -> np.ndarray:
    return np.abs(x) ** power * np.sign(x)


def observer_step(
    state: ObserverState,
    v_ticks: Iterable[np.ndarray],
    u_applied: np.ndarray,
    h: float,
    config: ObserverConfig,
) -> ObserverState:
    """Run the observer over one control step of ``S`` inner ticks with ``u`` held.

    The loop runs over inner ticks (time integration, inherently sequential); every tick works on
    the whole batch.

    Args:
        state: current observer state, arrays (..., 3).
        v_ticks: S arrays (..., 3) (or an (S, ..., 3) array): measured velocity at the start of
            each tick [m/s].
        u_applied: (..., 3) applied input held over the step (u_n + u_d after clipping) [m/s^2].
        h: tick length [s].
        config: observer gains.

    Returns:
        The new state (the input state is not modified).
    """
    c = config
    v_hat, s0, d_hat, e_prev = (
        a.copy() for a in (state.v_hat, state.s0, state.d_hat, state.e_prev)
    )
    h_u = h * u_applied
    s0_gain = h / (c.pi2 * c.lambda2)
    switch_gain = h * (c.eta + c.rho) if c.literal_sign_law else h * c.eta
    linear_gain = 0.0 if c.literal_sign_law else h * c.rho
    # λ1 = 2, λ2 = 1.5 (the defaults) reduce every power to abs/sqrt: about 3x fewer ufunc calls.
    square_root_law = c.lambda1 == 2.0 and c.lambda2 == 1.5
    # Preallocated work arrays: at B = 4096 the temporaries, not the arithmetic, dominate.
    e, e_dot, slope, work, surface = (np.empty_like(v_hat) for _ in range(5))
    for v in v_ticks:
        np.subtract(v, v_hat, out=e)
        np.subtract(e, e_prev, out=e_dot)
        e_dot /= h
        e_prev[...] = e
        np.abs(e, out=slope)  # |e|^(λ1-1) for λ1 = 2
        if square_root_law:
            root = np.sqrt(np.abs(e_dot, out=work), out=work)
            sig_l2 = e_dot * root  # sig^1.5(e')
            sig_2ml2 = np.copysign(root, e_dot, out=work)  # sig^0.5(e')
            sig_2ml2[e_dot == 0.0] = 0.0
        else:
            np.power(slope, c.lambda1 - 1.0, out=slope)
            sig_l2 = _sig(e_dot, c.lambda2)
            sig_2ml2 = _sig(e_dot, 2.0 - c.lambda2)
        # s = e + Π1 sig^λ1(e) + Π2 sig^λ2(e') = e (1 + Π1 |e|^(λ1-1)) + Π2 sig^λ2(e')
        np.multiply(slope, c.pi1, out=surface)
        surface += 1.0
        surface *= e
        sig_l2 *= c.pi2
        surface += sig_l2
        v_hat += h_u
        v_hat += h * (s0 + d_hat)
        slope *= s0_gain * c.pi1 * c.lambda1
        slope += s0_gain
        slope *= sig_2ml2
        s0 += slope
        if linear_gain:
            d_hat += linear_gain * surface
        d_hat += switch_gain * np.sign(surface, out=surface)
    return ObserverState(v_hat, s0, d_hat, e_prev)


def observer_step_held(
    state: ObserverState,
    v0: np.ndarray,
    accel: np.ndarray,
    u_applied: np.ndarray,
    dt: float,
    config: ObserverConfig,
    compiled: bool | None = None,
) -> ObserverState:
    """One control step of the observer for a plant with ``accel`` held (exact tick velocities).

    Uses the compiled kernel of :mod:`~uav_formation_env.core.observer_kernel` when numba is
    installed (same arithmetic, same numbers), else :func:`observer_step` on
    :func:`tick_velocities`.

    Args:
        state: current observer state, arrays (..., 3).
        v0: (..., 3) velocity at the start of the step [m/s].
        accel: (..., 3) held total acceleration u + d [m/s^2].
        u_applied: (..., 3) applied input [m/s^2].
        dt: control step [s].
        config: observer gains (``substeps`` ticks per step).
        compiled: force the kernel (True) or the numpy loop (False); None picks the kernel if
            available.
    """
    use_kernel = observer_kernel.AVAILABLE if compiled is None else compiled
    if not use_kernel:
        ticks = tick_velocities(v0, accel, dt, config.substeps)
        return observer_step(state, ticks, u_applied, dt / config.substeps, config)
    new = state.copy()
    c = config
    gains = np.array([c.pi1, c.lambda1, c.pi2, c.lambda2, c.eta, c.rho])
    flat = [np.ascontiguousarray(a, dtype=float).reshape(-1) for a in (v0, accel, u_applied)]
    observer_kernel.compiled_step(
        *flat,
        float(dt),
        int(c.substeps),
        new.v_hat.reshape(-1),
        new.s0.reshape(-1),
        new.d_hat.reshape(-1),
        new.e_prev.reshape(-1),
        gains,
        bool(c.literal_sign_law),
        bool(c.lambda1 == 2.0 and c.lambda2 == 1.5),
    )
    return new


def disturbance_estimate(state: ObserverState, config: ObserverConfig) -> np.ndarray:
    """Estimate of the disturbance, (..., 3) [m/s^2]: ``d_hat + s0`` (or ``d_hat`` if literal)."""
    if config.estimate_without_s0:
        return state.d_hat.copy()
    return state.d_hat + state.s0


def compensation(state: ObserverState, config: ObserverConfig) -> np.ndarray:
    """Feed-forward input that cancels the estimate, ``u_d = -estimate``, (..., 3) [m/s^2]."""
    return -disturbance_estimate(state, config)


def tick_velocities(
    v0: np.ndarray, a: np.ndarray, dt: float, substeps: int
) -> Iterator[np.ndarray]:
    """Velocity at the start of each inner tick with ``a`` held (exact), S arrays (..., 3) [m/s].

    Lazy, so that a large batch never holds all S samples at once.

    Args:
        v0: (..., 3) velocity at the start of the control step [m/s].
        a: (..., 3) held total acceleration u + d [m/s^2].
        dt: control step [s].
        substeps: S.
    """
    h = dt / substeps
    return (v0 + (k * h) * a for k in range(substeps))
