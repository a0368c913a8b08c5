"""External disturbances in the acceleration channel (docs/model.md §2), seeded through a passed
Generator.

The total disturbance of UAV i (0-based index, paper's UAV i+1) is the sum of

* the paper's eq. 21: ``(-1)^(i+1) A [sin(ωt), cos(ωt), sin(ωt)] + c r_i(t)`` with ω = 2π/period and
  ``r_i ~ U[0,1)^3`` redrawn per UAV, per axis and per control step and held over the step
  (``scalar_rand`` draws one scalar for the three axes, the literal MATLAB reading);
* a constant wind ``w``;
* a first-order Gauss-Markov gust ``g_{k+1} = φ g_k + σ sqrt(1 - φ²) ξ_k`` with φ = exp(-δ/τ) and
  ``ξ_k ~ N(0, I)``; ``g_0`` is drawn from the stationary law N(0, σ² I).

Randomness is split from evaluation: :meth:`Disturbance.draw_noise` draws standard noise for a block
of steps from a Generator, :meth:`Disturbance.evaluate` turns it into accelerations. The simulator
keeps one Generator per scenario copy and draws in blocks, so copy ``b`` of a batch reproduces a
single simulation seeded alike, bit for bit.

Backends (core/array_api.py): the draws stay on numpy Generators (one per copy, whatever the
backend); :func:`paper_sinusoid`, :class:`CopyDisturbance` and :meth:`Disturbance.evaluate` take
numpy arrays or torch tensors, so a torch simulator moves the drawn noise block to its device and
evaluates there.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import ModuleType
from typing import Any

import numpy as np

from uav_formation_env.config import DisturbanceConfig
from uav_formation_env.core.array_api import (
    as_float,
    constant_like,
    device,
    float_dtype,
    is_numpy,
    namespace,
    read_only,
)

_NUMPY = (np.ndarray, np.generic, float, int, list, tuple)  # times np.asarray takes


@lru_cache(maxsize=32)
def _signed_amplitude(n_uav: int, amplitude: float) -> np.ndarray:
    """(N, 1) ``A (-1)^i`` (i 1-based) of eq. 21 [m/s^2], cached and read-only."""
    sign = np.where(np.arange(1, n_uav + 1) % 2 == 1, -1.0, 1.0)
    signed = amplitude * sign[:, None]
    read_only(signed)
    return signed


def paper_sinusoid(t: Any, n_uav: int, amplitude: float, period: float) -> Any:
    """Deterministic part of eq. 21.

    Args:
        t: (B,) time [s], numpy (or a float) or torch.
        n_uav: N.
        amplitude: A [m/s^2].
        period: 2π/ω [s] (40 s in the paper, sin(π t / 20)).

    Returns:
        (B, N, 3) [m/s^2] of ``t``'s library and device (a new array); odd paper UAVs (1, 3, 5)
        get the negative sign.
    """
    # numpy and Python numbers skip the namespace look-up
    xp = np if isinstance(t, _NUMPY) else namespace(t)
    return _paper_sinusoid(xp, t, n_uav, amplitude, period)


def _paper_sinusoid(xp: ModuleType, t: Any, n_uav: int, amplitude: float, period: float) -> Any:
    """:func:`paper_sinusoid` in the namespace ``xp`` of ``t`` that the caller already has.

    The numpy path names no dtype or device and converts nothing but ``t``: the generic
    spellings are slower at small B).
    """
    numpy = is_numpy(xp)
    phase = 2.0 * np.pi * (np.asarray(t, dtype=float) if numpy else as_float(t)) / period
    sine = xp.sin(phase)
    # [sin, cos, sin] by assignment into one array: np.stack costs more than the trigonometry
    shape = (*phase.shape, 3)  # (B, 3)
    wave = np.empty(shape) if numpy else xp.empty(shape, dtype=phase.dtype, device=device(phase))
    wave[..., 0] = sine
    wave[..., 1] = xp.cos(phase)
    wave[..., 2] = sine
    signed = _signed_amplitude(n_uav, amplitude)  # (N, 1), cached
    if not numpy:
        signed = constant_like(signed, phase)  # converted once per device and dtype
    return signed * wave[..., None, :]


@dataclass
class CopyDisturbance:
    """Per-copy disturbance parameters, for scene distributions that draw them per reset.

    Attributes (numpy arrays or torch tensors, of one library, dtype and device):
        amplitude: (B, 1, 1) eq. 21 amplitude A [m/s^2].
        wind: (B, 1, 3) constant wind [m/s^2].
        gust_std: (B, 1, 1) stationary gust std σ [m/s^2].
    """

    amplitude: Any
    wind: Any
    gust_std: Any

    @classmethod
    def of(cls, config: DisturbanceConfig, batch: int, like: Any = None) -> CopyDisturbance:
        """Every copy with the parameters of ``config``.

        Args:
            config: the parameters of every copy.
            batch: B.
            like: an array whose library, device and (floating) dtype the arrays take; None:
                numpy float64.
        """
        xp, dtype = namespace(like), float_dtype(like)
        where = "cpu" if like is None else device(like)

        def full(value: Any, shape: tuple[int, ...]) -> Any:
            row = xp.asarray(value, dtype=dtype, device=where)
            return xp.asarray(xp.broadcast_to(row, shape), copy=True)  # writable, per copy

        return cls(
            amplitude=full(config.amplitude, (batch, 1, 1)),
            wind=full(config.wind, (batch, 1, 3)),
            gust_std=full(config.gust_std, (batch, 1, 1)),
        )

    def set_copy(self, copy: int, config: DisturbanceConfig) -> None:
        """Take copy ``copy``'s parameters from ``config``."""
        xp = namespace(self.wind)
        self.amplitude[copy] = config.amplitude
        self.wind[copy] = xp.asarray(config.wind, dtype=self.wind.dtype, device=device(self.wind))
        self.gust_std[copy] = config.gust_std


class Disturbance:
    """The configured disturbance model for N UAVs with control step ``dt``.

    Args:
        config: the scenario's disturbance section.
        n_uav: number of UAVs N.
        dt: control step δ [s]; the random parts are held over it.
    """

    def __init__(self, config: DisturbanceConfig, n_uav: int, dt: float) -> None:
        self.config = config
        self.n_uav = n_uav
        self.dt = dt
        uses_paper = config.model == "paper" and config.noise_scale > 0
        self.uniform_dim = (1 if config.scalar_rand else 3) if uses_paper else 0
        self.gust_dim = 3 if config.gust_std > 0 else 0
        self.gust_decay = float(np.exp(-dt / config.gust_time_constant))
        # Python floats (not numpy scalars), so that products with torch tensors stay tensors
        self._innovation_factor = float(np.sqrt(1.0 - self.gust_decay**2))
        self._innovation_scale = config.gust_std * self._innovation_factor
        self._wind = np.asarray(config.wind, dtype=float)

    @property
    def noise_dim(self) -> int:
        """Standard random numbers drawn per UAV per control step."""
        return self.uniform_dim + self.gust_dim

    def draw_noise(self, rng: np.random.Generator, n_steps: int) -> np.ndarray:
        """Standard noise for ``n_steps`` control steps of one scenario copy.

        Returns:
            (n_steps, N, noise_dim): U[0,1) columns first, then N(0,1) columns.
        """
        shape = (n_steps, self.n_uav)
        uniform = rng.random((*shape, self.uniform_dim))
        normal = rng.standard_normal((*shape, self.gust_dim))
        return np.concatenate((uniform, normal), axis=-1)

    def initial_gust(self, rng: np.random.Generator, gust_std: float | None = None) -> np.ndarray:
        """Gust state at t = 0 for one copy, (N, 3) [m/s^2], from the stationary law.

        Args:
            rng: the copy's generator.
            gust_std: the copy's σ (None: the configuration's); the normal draw is made whenever
                the layout has gust noise, so that a seed's draws do not depend on σ.
        """
        if self.gust_dim == 0:
            return np.zeros((self.n_uav, 3))
        std = self.config.gust_std if gust_std is None else gust_std
        return std * rng.standard_normal((self.n_uav, 3))

    def evaluate(
        self,
        t: Any,
        noise: Any,
        gust: Any,
        per_copy: CopyDisturbance | None = None,
    ) -> tuple[Any, Any]:
        """Disturbance held over the step starting at ``t``, and the next gust state.

        numpy arrays or torch tensors: ``noise``, ``gust`` and ``per_copy`` of one library and
        device (a torch caller moves the numpy-drawn noise there); ``t`` may also be numpy or a
        float then.

        Args:
            t: (B,) step start time [s].
            noise: (B, N, noise_dim) this step's standard noise (from :meth:`draw_noise`).
            gust: (B, N, 3) current gust state [m/s^2].
            per_copy: amplitude, wind and gust σ of each copy (None: the configuration's).

        Returns:
            ``(d, gust_next)``, each (B, N, 3) [m/s^2], new arrays of ``gust``'s library.
        """
        cfg = self.config
        xp = np  # numpy skips the namespace look-up
        wind = self._wind if per_copy is None else per_copy.wind
        if not isinstance(gust, np.ndarray):  # torch: the constants and t onto gust's device
            xp = namespace(gust)
            t = as_float(t, gust)  # a numpy t or a float converted; a tensor t as it is
            if per_copy is None:
                wind = constant_like(self._wind, gust)  # converted once per device and dtype
        d = wind + gust  # a new array, so the sums below may run in place
        if cfg.model == "paper":
            if per_copy is None:
                d += _paper_sinusoid(xp, t, self.n_uav, cfg.amplitude, cfg.period)
            else:
                d += per_copy.amplitude * _paper_sinusoid(xp, t, self.n_uav, 1.0, cfg.period)
            if self.uniform_dim:
                d += cfg.noise_scale * noise[..., : self.uniform_dim]
        if self.gust_dim:
            scale = self._innovation_scale
            if per_copy is not None:
                scale = per_copy.gust_std * self._innovation_factor
            innovation = scale * noise[..., self.uniform_dim :]
            gust = self.gust_decay * gust + innovation
        return d, gust

    def bound(self) -> float:
        """Deterministic per-axis bound of the eq. 21 and wind parts [m/s^2] (gust unbounded)."""
        cfg = self.config
        paper = cfg.amplitude + cfg.noise_scale if cfg.model == "paper" else 0.0
        return paper + float(np.abs(self._wind).max())
