"""The array-API shim (core/array_api.py) and the dynamics on both backends.

numpy is the reference; torch (float64, on the CPU in CI, on CUDA when present) must give the
same numbers. The other core modules have their own tests/test_backend_*.py files.
"""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env.core import array_api
from uav_formation_env.core.dynamics import rollout, zoh_step

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def test_namespace_is_numpy_itself_for_numpy_and_scalars():
    assert array_api.namespace(np.zeros(2), 1.0, None, np.float64(2.0)) is np
    assert array_api.namespace() is np
    xp = array_api.namespace(np.zeros(2), torch.zeros(2))
    assert not array_api.is_numpy(xp) and xp.__name__ == "array_api_compat.torch"


def test_namespace_of_backend_names_the_choices():
    assert array_api.namespace_of_backend("numpy") is np
    assert array_api.namespace_of_backend("torch").__name__ == "array_api_compat.torch"
    with pytest.raises(ValueError, match=r"backend must be one of \('numpy', 'torch'\), got 'jax'"):
        array_api.namespace_of_backend("jax")


def test_copy_and_batch_moves_never_share_memory():
    for x in (np.arange(6.0).reshape(2, 3), torch.arange(6.0).reshape(2, 3)):
        for y in (array_api.copy(x), array_api.move_batch_last(x)):
            y[0, 0] = 99.0
            assert float(x[0, 0]) == 0.0
        last = array_api.move_batch_last(x)
        assert tuple(last.shape) == (3, 2)
        np.testing.assert_array_equal(array_api.to_numpy(array_api.move_batch_first(last)), x)
    one = torch.arange(3.0)  # 1-D: the permutation is the identity, the copy must still be new
    array_api.move_batch_last(one)[0] = 5.0
    assert float(one[0]) == 0.0


def test_add_at_accumulates_repeated_indices():
    for make in (np.asarray, torch.as_tensor):
        target = make(np.zeros((3, 2)))
        array_api.add_at(target, make(np.array([0, 2, 0])), make(np.ones((3, 2))))
        np.testing.assert_array_equal(array_api.to_numpy(target), [[2, 2], [0, 0], [1, 1]])


def test_einsum_agrees():
    a, b = np.arange(6.0).reshape(2, 3), np.arange(12.0).reshape(3, 4)
    expected = np.einsum("ij,jk->ik", a, b)
    got = array_api.einsum("ij,jk->ik", torch.from_numpy(a), torch.from_numpy(b))
    np.testing.assert_array_equal(array_api.to_numpy(got), expected)


@pytest.mark.parametrize("device", DEVICES)
def test_dynamics_equal_on_torch(device):
    rng = np.random.default_rng(0)
    z, a = rng.normal(size=(4, 5, 6)), rng.normal(size=(4, 5, 3))
    inputs = rng.normal(size=(4, 5, 7, 3))

    def on(x):
        return torch.as_tensor(x, device=device)

    tol = dict(rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        array_api.to_numpy(zoh_step(on(z), on(a), 0.2)), zoh_step(z, a, 0.2), **tol
    )
    np.testing.assert_allclose(
        array_api.to_numpy(rollout(on(z), on(inputs), 0.2)),
        rollout(z, inputs, 0.2),
        **tol,
    )
    # the closed form of the exact ZOH step: p + v dt + a dt^2 / 2
    step = array_api.to_numpy(zoh_step(on(z), on(a), 0.2))
    np.testing.assert_allclose(step[..., :3], z[..., :3] + 0.2 * z[..., 3:] + 0.02 * a, **tol)
