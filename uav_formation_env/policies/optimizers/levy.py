"""Lévy-flight steps by Mantegna's algorithm (docs/model.md §6.3, eq. 19 of the paper).

A step is ``s = mu / |nu|**(1/beta)`` with ``mu ~ N(0, sigma_mu**2)`` and ``nu ~ N(0, 1)``, drawn
independently per component. For large ``|s|`` the ratio has a power-law tail,
``P(|s| > x) ~ x**(-beta)``, which gives LFPIO its occasional long jumps. The paper reuses δ for
the exponent and gives no value; docs/model.md renames it β and fixes β = 1.5 (σ_μ = 0.696575).

All randomness comes from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from uav_formation_env.core.array_api import namespace_of

__all__ = [
    "DEFAULT_BETA",
    "TINY",
    "levy_denominator_into",
    "levy_steps",
    "levy_steps_into",
    "mantegna_components",
    "mantegna_sigma",
]

DEFAULT_BETA = 1.5

# Smallest positive normal double: keeps the denominator non-zero so that an (astronomically
# unlikely) nu == 0 gives a huge but finite step, never inf or 0/0 = nan.
TINY = np.finfo(np.float64).tiny


@lru_cache(maxsize=16)
def mantegna_sigma(beta: float) -> float:
    """Scale σ_μ of the numerator of Mantegna's Lévy step.

    σ_μ = [Γ(1+β) sin(πβ/2) / (Γ((1+β)/2) β 2^((β-1)/2))]^(1/β).

    Args:
        beta: Stability exponent, 0 < beta < 2. At beta = 2 the formula gives σ_μ = 0 (a Gaussian
            limit with no Lévy part), so it is rejected.

    Returns:
        σ_μ (0.696575... for beta = 1.5). Cached per beta (LFPIO asks for it every iteration).

    Raises:
        ValueError: If beta is not a finite number in (0, 2).
    """
    if not (isinstance(beta, (int, float)) and math.isfinite(beta) and 0.0 < beta < 2.0):
        raise ValueError(f"invalid field 'levy_beta': must be in (0, 2), got {beta!r}")
    numerator = math.gamma(1.0 + beta) * math.sin(math.pi * beta / 2.0)
    denominator = math.gamma((1.0 + beta) / 2.0) * beta * 2.0 ** ((beta - 1.0) / 2.0)
    return (numerator / denominator) ** (1.0 / beta)


def mantegna_components(
    rng: np.random.Generator, shape: int | tuple[int, ...], beta: float = DEFAULT_BETA
) -> tuple[np.ndarray, np.ndarray]:
    """Draw the two Gaussian components of Mantegna's step.

    Exposed so that the distribution of μ can be tested; :func:`levy_steps` draws exactly these
    (same order of draws from ``rng``) and combines them.

    Args:
        rng: Random generator (the only source of randomness).
        shape: Output shape.
        beta: Stability exponent in (0, 2).

    Returns:
        ``(mu, nu)``, each of ``shape``: ``mu ~ N(0, mantegna_sigma(beta)**2)``, ``nu ~ N(0, 1)``.
    """
    sigma = mantegna_sigma(beta)
    mu = sigma * rng.standard_normal(shape)
    nu = rng.standard_normal(shape)
    return mu, nu


def levy_steps(
    rng: np.random.Generator, shape: int | tuple[int, ...], beta: float = DEFAULT_BETA
) -> np.ndarray:
    """Independent Lévy steps ``s = mu / |nu|**(1/beta)`` (Mantegna 1994).

    Args:
        rng: Random generator (the only source of randomness).
        shape: Output shape, e.g. ``(*batch, P, n)`` for one step per pigeon component.
        beta: Stability exponent in (0, 2); default 1.5.

    Returns:
        Array of ``shape`` of symmetric, heavy-tailed steps (tail index ``beta``).
    """
    shape = (shape,) if isinstance(shape, int | np.integer) else tuple(shape)
    return levy_steps_into(rng, np.empty((2, *shape)), beta)


def levy_steps_into(rng: np.random.Generator, work: np.ndarray, beta: float) -> np.ndarray:
    """:func:`levy_steps` of shape ``work.shape[1:]``, computed in the buffer ``work``.

    Draws ``mu`` and ``nu`` with one ``standard_normal`` call: the same numbers, in the same order,
    as :func:`mantegna_components` (two calls).

    Args:
        rng: Random generator (the only source of randomness).
        work: ``(2, *shape)`` C-contiguous float64 buffer, overwritten (numpy, or a tensor
            for a ``rng`` that draws on its device).
        beta: Stability exponent in (0, 2).

    Returns:
        ``work[0]``, the steps (a view into ``work``).
    """
    sigma = mantegna_sigma(beta)
    rng.standard_normal(out=work)
    mu, nu = work[0], work[1]
    xp = namespace_of(work)
    xp.multiply(mu, sigma, out=mu)
    levy_denominator_into(nu, beta)
    xp.maximum(nu, TINY, out=nu)
    return xp.divide(mu, nu, out=mu)


def levy_denominator_into(nu: np.ndarray, beta: float) -> np.ndarray:
    """``|nu|**(1/beta)`` in place (without the guard against 0).

    For ``beta = 1.5`` this is ``cbrt(nu * nu)``, about 4x faster than the power and equal to it
    up to an ulp or two (floating-point rounding; ``1/1.5`` is not exactly 2/3 in binary).

    Args:
        nu: float64 array (numpy or torch), overwritten.
        beta: Stability exponent in (0, 2).

    Returns:
        ``nu``.
    """
    if not isinstance(nu, np.ndarray):  # torch has no cbrt: the power, to an ulp or two
        return nu.abs_().pow_(1.0 / beta)
    if beta == 1.5:
        np.multiply(nu, nu, out=nu)
        return np.cbrt(nu, out=nu)
    np.abs(nu, out=nu)
    return np.power(nu, 1.0 / beta, out=nu)
