"""The counter-based generator (core/counter_rng.py): Philox4x32-10 against the Random123
known-answer vectors, the same bits on numpy and torch, rows independent of each other, and
uniforms and normals with the right distribution."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uav_formation_env.core.counter_rng import key_words, philox4x32, standard_normal, uniform

# Random123's kat_vectors, "philox4x32 10": counter (4 words), key (2 words) -> output (4 words)
KAT = [
    ([0, 0, 0, 0], [0, 0], [0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8]),
    ([0xFFFFFFFF] * 4, [0xFFFFFFFF] * 2, [0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD]),
    (
        [0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344],
        [0xA4093822, 0x299F31D0],
        [0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1],
    ),
]


def libraries():
    libs = [("numpy", np.asarray)]
    try:
        import torch
    except ImportError:
        return libs
    libs.append(("torch", lambda a: torch.as_tensor(np.asarray(a), dtype=torch.int64)))
    if torch.cuda.is_available():
        libs.append(("cuda", lambda a: torch.as_tensor(np.asarray(a), device="cuda")))
    return libs


def host(x) -> np.ndarray:
    return x if isinstance(x, np.ndarray) else x.cpu().numpy()


@pytest.mark.parametrize(("name", "array"), libraries(), ids=[n for n, _ in libraries()])
def test_philox_known_answers(name, array) -> None:
    counters = array(np.array([c for c, _, _ in KAT], dtype=np.int64))
    keys = array(np.array([k for _, k, _ in KAT], dtype=np.int64))
    expected = np.array([o for _, _, o in KAT], dtype=np.int64)
    np.testing.assert_array_equal(host(philox4x32(counters, keys)), expected)


def draw_args(rows: int):
    rng = np.random.default_rng(1)
    keys = rng.integers(0, 2**32, (rows, 2), dtype=np.int64)
    words = rng.integers(0, 2**32, (rows, 3), dtype=np.int64)
    return keys, words


@pytest.mark.parametrize(("name", "array"), libraries()[1:], ids=[n for n, _ in libraries()[1:]])
def test_torch_draws_the_numpy_numbers(name, array) -> None:
    keys, words = draw_args(6)
    u = uniform(keys, words, (40, 3))
    np.testing.assert_array_equal(host(uniform(array(keys), array(words), (40, 3))), u)
    z = standard_normal(keys, words, (40, 3))
    got = host(standard_normal(array(keys), array(words), (40, 3)))
    np.testing.assert_allclose(got, z, rtol=1e-13, atol=1e-13)  # log and cos: an ulp or two


def test_a_row_draws_the_same_alone_and_in_any_batch() -> None:
    keys, words = draw_args(5)
    together = uniform(keys, words, (7,))
    for row in range(5):
        alone = uniform(keys[row : row + 1], words[row : row + 1], (7,))
        np.testing.assert_array_equal(alone[0], together[row])
    # a different word or key gives different numbers
    other = words.copy()
    other[:, 0] += 1
    assert not np.isin(uniform(keys, other, (7,)), together).any()


def test_uniforms_and_normals_have_their_distributions() -> None:
    keys, words = draw_args(4)
    u = uniform(keys, words, (50_000,)).ravel()
    assert u.min() >= 0.0 and u.max() < 1.0
    quantiles = np.quantile(u, [0.1, 0.5, 0.9])
    np.testing.assert_allclose(quantiles, [0.1, 0.5, 0.9], atol=0.005)
    z = standard_normal(keys, words, (50_000,)).ravel()
    assert abs(z.mean()) < 0.01 and abs(z.std() - 1.0) < 0.01
    # the normal CDF at -1, 0, 1 (Phi = 0.1587, 0.5, 0.8413)
    below = [(z < x).mean() for x in (-1.0, 0.0, 1.0)]
    phi = [0.5 * (1 + math.erf(x / math.sqrt(2))) for x in (-1.0, 0.0, 1.0)]
    np.testing.assert_allclose(below, phi, atol=0.005)


def test_key_words_split_a_seed_and_refuse_others() -> None:
    np.testing.assert_array_equal(key_words(2**32 + 5), [5, 1])
    with pytest.raises(ValueError, match="seed must be an integer in"):
        key_words(-1)
