"""A counter-based random generator that numpy and torch compute alike, on any device.

Philox4x32-10 (Salmon et al., "Parallel random numbers: as easy as 1, 2, 3", SC 2011; the
generator of cuRAND and of JAX) maps a 128-bit counter and a 64-bit key to 128 random bits with
integer arithmetic only. A random number is then a pure function of *what it is for*: here of
(key = episode seed and stream, counter = element, draw, UAV, control step). Nothing is carried
from one draw to the next, so

- a copy's numbers do not depend on the batch it runs in, nor on which other UAVs draw;
- numpy and torch (CPU or CUDA) give the same bits: uniforms are bit-identical on both
  libraries, normals agree to the last ulp or two of ``log``/``cos`` (the libraries' own
  transcendental functions);
- a GPU draws its numbers where it uses them, with no per-copy loop on the host.

Words are 32-bit values held in int64 arrays (both libraries have int64 on every device; torch's
uint32 lacks multiplication on some). The 32 x 32-bit products are split into 16-bit halves so
that no intermediate exceeds 2^49: signed overflow is never relied on.

Checked against the Random123 known-answer vectors (``tests/test_counter_rng.py``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uav_formation_env.core.array_api import device, namespace_of

__all__ = ["MASK32", "key_words", "philox4x32", "standard_normal", "uniform"]

MASK32 = 0xFFFFFFFF
PHILOX_M0, PHILOX_M1 = 0xD2511F53, 0xCD9E8D57  # round multipliers
PHILOX_W0, PHILOX_W1 = 0x9E3779B9, 0xBB67AE85  # key schedule (Weyl) increments
ROUNDS = 10


def _mulhilo(multiplier: int, word: Any) -> tuple[Any, Any]:
    """High and low 32 bits of ``multiplier * word`` (both < 2^32), without 64-bit overflow."""
    low_half, high_half = word & 0xFFFF, word >> 16
    product_low = multiplier * low_half  # < 2^48
    product_high = multiplier * high_half  # < 2^48
    middle = product_low + ((product_high & 0xFFFF) << 16)  # < 2^49
    return (product_high >> 16) + (middle >> 32), middle & MASK32


def philox4x32(counter: Any, key: Any, rounds: int = ROUNDS) -> Any:
    """Philox4x32-R of counters and keys.

    Args:
        counter: (..., 4) int64 words in [0, 2^32).
        key: (..., 2) int64 words in [0, 2^32), broadcastable against ``counter[..., :2]``.
        rounds: R (10 is the standard, cryptanalysed choice).

    Returns:
        (..., 4) int64 words in [0, 2^32): the random bits.
    """
    xp = namespace_of(counter)
    c0, c1, c2, c3 = (counter[..., k] for k in range(4))
    k0, k1 = key[..., 0], key[..., 1]
    for r in range(rounds):
        if r:
            k0 = (k0 + PHILOX_W0) & MASK32
            k1 = (k1 + PHILOX_W1) & MASK32
        hi0, lo0 = _mulhilo(PHILOX_M0, c0)
        hi1, lo1 = _mulhilo(PHILOX_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    return xp.stack(xp.broadcast_arrays(c0, c1, c2, c3), axis=-1)


def _bits(key: Any, words: Any, count: int) -> Any:
    """(rows, count, 4) Philox bits of counters (c, words[:, 0], words[:, 1], words[:, 2]) for
    c = 0 .. count - 1, under each row's key."""
    xp = namespace_of(key)
    rows = key.shape[0]
    element = xp.reshape(xp.arange(count, dtype=key.dtype, device=device(key)), (1, count))
    per_row = [xp.reshape(words[:, k], (rows, 1)) for k in range(3)]
    counter = xp.stack(xp.broadcast_arrays(element, *per_row), axis=-1)
    return philox4x32(counter, xp.reshape(key, (rows, 1, 2)))


def _unit(high: Any, low: Any) -> Any:
    """53-bit U[0, 1) doubles from two 32-bit words (27 + 26 bits; exact in float64)."""
    xp = namespace_of(high)
    mantissa = (high >> 5) * 67108864 + (low >> 6)
    return xp.astype(mantissa, xp.float64) * (1.0 / 9007199254740992.0)  # / 2^53


def _pairs(pair: Any, size: tuple[int, ...]) -> Any:
    """(rows, P, 2) values, two per counter, as (rows, *size): element e is value e % 2 of
    counter e // 2."""
    xp = namespace_of(pair)
    rows, count = pair.shape[0], math.prod(size)
    flat = xp.reshape(pair, (rows, 2 * pair.shape[1]))[:, :count]
    return xp.reshape(flat, (rows, *size))


def uniform(key: Any, words: Any, size: tuple[int, ...]) -> Any:
    """U[0, 1) doubles with 53 random bits, one per element (two per Philox counter).

    Args:
        key: (rows, 2) int64 key words of each row (its stream).
        words: (rows, 3) int64 counter words 1-3 of each row (e.g. draw, UAV, step), in
            [0, 2^32); word 0 counts pairs of elements (element e uses counter e // 2).
        size: the per-row shape (elements in C order).

    Returns:
        (rows, *size) float64, in the library and on the device of ``key``; bit-identical on
        numpy and torch.
    """
    xp = namespace_of(key)
    bits = _bits(key, words, (math.prod(size) + 1) // 2)
    pair = xp.stack((_unit(bits[..., 0], bits[..., 1]), _unit(bits[..., 2], bits[..., 3])), axis=-1)
    return _pairs(pair, size)


def standard_normal(key: Any, words: Any, size: tuple[int, ...]) -> Any:
    """N(0, 1) doubles, one per element, by the Box-Muller transform: the two 53-bit uniforms of
    a Philox counter give two independent normals (``r cos θ``, ``r sin θ``).

    Args: as :func:`uniform`.

    Returns:
        (rows, *size) float64 in the library and on the device of ``key``.
    """
    xp = namespace_of(key)
    bits = _bits(key, words, (math.prod(size) + 1) // 2)
    u1, u2 = _unit(bits[..., 0], bits[..., 1]), _unit(bits[..., 2], bits[..., 3])
    radius = xp.sqrt(-2.0 * xp.log(1.0 - u1))  # 1 - u1 in (0, 1]: the log is finite
    angle = (2.0 * math.pi) * u2
    return _pairs(xp.stack((radius * xp.cos(angle), radius * xp.sin(angle)), axis=-1), size)


def key_words(seed: int) -> np.ndarray:
    """(2,) int64 key words of a non-negative integer seed below 2^64."""
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise ValueError(f"seed must be an integer in [0, 2^64), got {seed}")
    return np.array([seed & MASK32, seed >> 32], dtype=np.int64)
