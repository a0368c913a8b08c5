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

Array-API functions: numpy arrays or torch tensors (core/array_api.py). numpy inputs take the
compiled kernel of :mod:`~uav_formation_env.core.observer_kernel` when numba is installed, or a
numpy loop with preallocated buffers; torch inputs take the array-API loop of the same arithmetic
(the same operations in the same order, so float64 gives the numpy numbers), eagerly or inside
the simulator's compiled step (``SimOptions(compile=True)``).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from uav_formation_env.config import ObserverConfig
from uav_formation_env.core import observer_kernel
from uav_formation_env.core.array_api import copy, device, is_numpy, namespace


@dataclass
class ObserverState:
    """Observer state, every array (..., 3): v_hat [m/s], s0 and d_hat [m/s^2], e_prev [m/s].

    The arrays are numpy arrays or torch tensors (all of one library and device).
    """

    v_hat: Any
    s0: Any
    d_hat: Any
    e_prev: Any

    def copy(self) -> ObserverState:
        """A state with new arrays (never shares memory with this one)."""
        return ObserverState(copy(self.v_hat), copy(self.s0), copy(self.d_hat), copy(self.e_prev))


def observer_init(v: Any) -> ObserverState:
    """Initial state: ``v_hat = v(0)``, zero estimates and zero previous error.

    Args:
        v: (..., 3) measured velocity [m/s], numpy (any real type, the state is float64) or torch
            (a floating tensor keeps its dtype, others become float64; the state lives on its
            device).
    """
    xp = namespace(v)
    dtype = xp.float64
    if not is_numpy(xp) and xp.isdtype(v.dtype, "real floating"):
        dtype = v.dtype  # e.g. float32 on a GPU
    v_hat = xp.asarray(v, dtype=dtype, copy=True)
    # xp.zeros, not xp.zeros_like: numpy's zeros_like is slower at small B
    zeros = [xp.zeros(v_hat.shape, dtype=dtype, device=device(v_hat)) for _ in range(3)]
    return ObserverState(v_hat, *zeros)


def _sig(x: Any, power: float) -> Any:
    """``sig^power(x) = |x|^power sign(x)``, elementwise (numpy or torch)."""
    xp = namespace(x)
    return xp.abs(x) ** power * xp.sign(x)


def observer_step(
    state: ObserverState,
    v_ticks: Iterable[Any],
    u_applied: Any,
    h: float,
    config: ObserverConfig,
) -> ObserverState:
    """Run the observer over one control step of ``S`` inner ticks with ``u`` held.

    The loop runs over inner ticks (time integration, inherently sequential); every tick works on
    the whole batch. numpy arrays or torch tensors (all of one library).

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
    xp = namespace(state.v_hat, u_applied)
    h_u = h * u_applied
    s0_gain = h / (c.pi2 * c.lambda2)
    slope_gain = s0_gain * c.pi1 * c.lambda1
    switch_gain = h * (c.eta + c.rho) if c.literal_sign_law else h * c.eta
    linear_gain = 0.0 if c.literal_sign_law else h * c.rho
    # λ1 = 2, λ2 = 1.5 (the defaults) reduce every power to abs/sqrt: about 3x fewer ufunc calls.
    square_root_law = c.lambda1 == 2.0 and c.lambda2 == 1.5
    gains = (h, h_u, s0_gain, slope_gain, switch_gain, linear_gain, square_root_law)
    if is_numpy(xp):
        return _numpy_ticks(state, v_ticks, c, *gains)
    v_hat, s0, d_hat, e_prev = state.v_hat, state.s0, state.d_hat, state.e_prev
    for v in v_ticks:
        e = v - v_hat
        e_dot = (e - e_prev) / h
        e_prev = e
        slope = xp.abs(e)  # |e|^(λ1-1) for λ1 = 2
        if square_root_law:
            root = xp.sqrt(xp.abs(e_dot))
            sig_l2 = e_dot * root  # sig^1.5(e')
            sig_2ml2 = xp.where(e_dot == 0.0, 0.0, xp.copysign(root, e_dot))  # sig^0.5(e')
        else:
            slope = slope ** (c.lambda1 - 1.0)
            sig_l2 = _sig(e_dot, c.lambda2)
            sig_2ml2 = _sig(e_dot, 2.0 - c.lambda2)
        # s = e + Π1 sig^λ1(e) + Π2 sig^λ2(e') = e (1 + Π1 |e|^(λ1-1)) + Π2 sig^λ2(e')
        surface = (slope * c.pi1 + 1.0) * e + sig_l2 * c.pi2
        v_hat = v_hat + h_u + h * (s0 + d_hat)
        s0 = s0 + (slope * slope_gain + s0_gain) * sig_2ml2
        if linear_gain:
            d_hat = d_hat + linear_gain * surface
        d_hat = d_hat + switch_gain * xp.sign(surface)
    return ObserverState(v_hat, s0, d_hat, e_prev)


def _numpy_ticks(
    state: ObserverState,
    v_ticks: Iterable[np.ndarray],
    c: ObserverConfig,
    h: float,
    h_u: np.ndarray,
    s0_gain: float,
    slope_gain: float,
    switch_gain: float,
    linear_gain: float,
    square_root_law: bool,
) -> ObserverState:
    """The tick loop of :func:`observer_step` on numpy, in preallocated buffers (``out=``).

    The same operations in the same order as the array-API loop (the same numbers, bit for bit;
    tests/test_backend_observer.py). Kept because the fresh temporaries of the array-API loop
    cost time at small B (benchmarks/bench_sim.py).
    """
    v_hat, s0, d_hat, e_prev = (
        a.copy() for a in (state.v_hat, state.s0, state.d_hat, state.e_prev)
    )
    e, e_dot, slope, work, surface = (np.empty_like(v_hat) for _ in range(5))
    for v in v_ticks:
        np.subtract(v, v_hat, out=e)
        np.subtract(e, e_prev, out=e_dot)
        e_dot /= h
        e_prev[...] = e
        np.abs(e, out=slope)
        if square_root_law:
            root = np.sqrt(np.abs(e_dot, out=work), out=work)
            sig_l2 = e_dot * root
            sig_2ml2 = np.copysign(root, e_dot, out=work)
            sig_2ml2[e_dot == 0.0] = 0.0
        else:
            np.power(slope, c.lambda1 - 1.0, out=slope)
            sig_l2 = _sig(e_dot, c.lambda2)
            sig_2ml2 = _sig(e_dot, 2.0 - c.lambda2)
        np.multiply(slope, c.pi1, out=surface)
        surface += 1.0
        surface *= e
        sig_l2 *= c.pi2
        surface += sig_l2
        v_hat += h_u
        v_hat += h * (s0 + d_hat)
        slope *= slope_gain
        slope += s0_gain
        slope *= sig_2ml2
        s0 += slope
        if linear_gain:
            d_hat += linear_gain * surface
        d_hat += switch_gain * np.sign(surface, out=surface)
    return ObserverState(v_hat, s0, d_hat, e_prev)


def observer_step_held(
    state: ObserverState,
    v0: Any,
    accel: Any,
    u_applied: Any,
    dt: float,
    config: ObserverConfig,
    compiled: bool | None = None,
) -> ObserverState:
    """One control step of the observer for a plant with ``accel`` held (exact tick velocities).

    numpy inputs use the compiled kernel of :mod:`~uav_formation_env.core.observer_kernel` when
    numba is installed (same arithmetic, same numbers), else :func:`observer_step` on
    :func:`tick_velocities`; torch inputs always take :func:`observer_step` (the kernel is
    numpy-only).

    Args:
        state: current observer state, arrays (..., 3).
        v0: (..., 3) velocity at the start of the step [m/s].
        accel: (..., 3) held total acceleration u + d [m/s^2].
        u_applied: (..., 3) applied input [m/s^2].
        dt: control step [s].
        config: observer gains (``substeps`` ticks per step).
        compiled: force the kernel (True) or the array loop (False); None picks the kernel if
            available and the inputs are numpy.

    Raises:
        TypeError: ``compiled=True`` with torch inputs.
    """
    # an isinstance test, not a namespace look-up (cheaper at small B)
    use_kernel = compiled
    if compiled is None:
        use_kernel = observer_kernel.AVAILABLE and isinstance(state.v_hat, np.ndarray)
    elif compiled and not is_numpy(namespace(state.v_hat, v0, accel, u_applied)):
        raise TypeError("compiled=True needs numpy arrays: the numba kernel is numpy-only")
    if not use_kernel:
        ticks = tick_velocities(v0, accel, dt, config.substeps)
        return observer_step(state, ticks, u_applied, dt / config.substeps, config)
    # numpy here: .copy() directly, without the shim's per-array type check
    new = ObserverState(
        state.v_hat.copy(), state.s0.copy(), state.d_hat.copy(), state.e_prev.copy()
    )
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


def disturbance_estimate(state: ObserverState, config: ObserverConfig) -> Any:
    """Estimate of the disturbance, (..., 3) [m/s^2]: ``d_hat + s0`` (or ``d_hat`` if literal).

    A new array of the state's library and device.
    """
    if config.estimate_without_s0:
        return copy(state.d_hat)
    return state.d_hat + state.s0


def compensation(state: ObserverState, config: ObserverConfig) -> Any:
    """Feed-forward input that cancels the estimate, ``u_d = -estimate``, (..., 3) [m/s^2]."""
    return -disturbance_estimate(state, config)


def tick_velocities(v0: Any, a: Any, dt: float, substeps: int) -> Iterator[Any]:
    """Velocity at the start of each inner tick with ``a`` held (exact), S arrays (..., 3) [m/s].

    Lazy, so that a large batch never holds all S samples at once. numpy arrays or torch tensors.

    Args:
        v0: (..., 3) velocity at the start of the control step [m/s].
        a: (..., 3) held total acceleration u + d [m/s^2].
        dt: control step [s].
        substeps: S.
    """
    h = dt / substeps
    return (v0 + (k * h) * a for k in range(substeps))
