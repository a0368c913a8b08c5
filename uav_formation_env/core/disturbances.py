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
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uav_formation_env.config import DisturbanceConfig


@lru_cache(maxsize=32)
def _signed_amplitude(n_uav: int, amplitude: float) -> np.ndarray:
    """(N, 1) ``A (-1)^i`` (i 1-based) of eq. 21 [m/s^2], cached and read-only."""
    sign = np.where(np.arange(1, n_uav + 1) % 2 == 1, -1.0, 1.0)
    signed = amplitude * sign[:, None]
    signed.flags.writeable = False
    return signed


def paper_sinusoid(t: np.ndarray, n_uav: int, amplitude: float, period: float) -> np.ndarray:
    """Deterministic part of eq. 21.

    Args:
        t: (B,) time [s].
        n_uav: N.
        amplitude: A [m/s^2].
        period: 2π/ω [s] (40 s in the paper, sin(π t / 20)).

    Returns:
        (B, N, 3) [m/s^2]; odd paper UAVs (1, 3, 5) get the negative sign.
    """
    phase = 2.0 * np.pi * np.asarray(t, dtype=float) / period
    sine = np.sin(phase)
    # [sin, cos, sin] by assignment into one array: np.stack costs more than the trigonometry
    wave = np.empty((*phase.shape, 3))  # (B, 3)
    wave[..., 0] = sine
    wave[..., 1] = np.cos(phase)
    wave[..., 2] = sine
    return _signed_amplitude(n_uav, amplitude) * wave[..., None, :]


@dataclass
class CopyDisturbance:
    """Per-copy disturbance parameters, for scene distributions that draw them per reset.

    Attributes:
        amplitude: (B, 1, 1) eq. 21 amplitude A [m/s^2].
        wind: (B, 1, 3) constant wind [m/s^2].
        gust_std: (B, 1, 1) stationary gust std σ [m/s^2].
    """

    amplitude: np.ndarray
    wind: np.ndarray
    gust_std: np.ndarray

    @classmethod
    def of(cls, config: DisturbanceConfig, batch: int) -> CopyDisturbance:
        """Every copy with the parameters of ``config``."""
        return cls(
            amplitude=np.full((batch, 1, 1), config.amplitude),
            wind=np.tile(np.asarray(config.wind, dtype=float), (batch, 1, 1)),
            gust_std=np.full((batch, 1, 1), config.gust_std),
        )

    def set_copy(self, copy: int, config: DisturbanceConfig) -> None:
        """Take copy ``copy``'s parameters from ``config``."""
        self.amplitude[copy] = config.amplitude
        self.wind[copy] = config.wind
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
        self._innovation_scale = config.gust_std * np.sqrt(1.0 - self.gust_decay**2)
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
        t: np.ndarray,
        noise: np.ndarray,
        gust: np.ndarray,
        per_copy: CopyDisturbance | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Disturbance held over the step starting at ``t``, and the next gust state.

        Args:
            t: (B,) step start time [s].
            noise: (B, N, noise_dim) this step's standard noise (from :meth:`draw_noise`).
            gust: (B, N, 3) current gust state [m/s^2].
            per_copy: amplitude, wind and gust σ of each copy (None: the configuration's).

        Returns:
            ``(d, gust_next)``, each (B, N, 3) [m/s^2].
        """
        cfg = self.config
        wind = self._wind if per_copy is None else per_copy.wind
        d = wind + gust  # a new array, so the sums below may run in place
        if cfg.model == "paper":
            if per_copy is None:
                d += paper_sinusoid(t, self.n_uav, cfg.amplitude, cfg.period)
            else:
                d += per_copy.amplitude * paper_sinusoid(t, self.n_uav, 1.0, cfg.period)
            if self.uniform_dim:
                d += cfg.noise_scale * noise[..., : self.uniform_dim]
        if self.gust_dim:
            scale = self._innovation_scale
            if per_copy is not None:
                scale = per_copy.gust_std * np.sqrt(1.0 - self.gust_decay**2)
            innovation = scale * noise[..., self.uniform_dim :]
            gust = self.gust_decay * gust + innovation
        return d, gust

    def bound(self) -> float:
        """Deterministic per-axis bound of the eq. 21 and wind parts [m/s^2] (gust unbounded)."""
        cfg = self.config
        paper = cfg.amplitude + cfg.noise_scale if cfg.model == "paper" else 0.0
        return paper + float(np.abs(self._wind).max())
