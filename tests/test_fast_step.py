"""The compiled step (fast_step.py, fast_kernels.py) gives the batched path's numbers bit for bit.

Two environments of one scenario and seed are stepped with the same actions, one through the
compiled kernels and one with the fast path removed (the batched numpy code, the one
definition); every observation, reward, flag, info and the simulators' whole state must be
equal (``np.array_equal``, no tolerance).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env import fast_kernels, fast_step, parallel_env
from uav_formation_env.config_io import paper_scenario, with_overrides
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.heuristic import consensus_pd
from uav_formation_env.scenarios import windy_scenario

pytestmark = pytest.mark.skipif(not fast_step.AVAILABLE, reason="needs numba (the [fast] extra)")

_RETURNS = ("observations", "rewards", "terminations", "truncations", "infos")
_SIM_STATE = ("z", "gust", "t", "steps", "noise", "noise_pos", "observer", "topology", "last")


def _equal(a, b, path: str) -> None:
    """Exact equality of nested dicts, dataclasses, arrays and numbers (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for key in a:
            _equal(a[key], b[key], f"{path}[{key!r}]")
    elif isinstance(a, tuple | list):
        assert type(a) is type(b) and len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b)):
            _equal(x, y, f"{path}[{k}]")
    elif dataclasses.is_dataclass(a):
        for field in dataclasses.fields(a):
            _equal(getattr(a, field.name), getattr(b, field.name), f"{path}.{field.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), path
        assert (a.dtype, a.shape) == (b.dtype, b.shape), path
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
    else:
        assert type(a) is type(b) and (a == b or (a != a and b != b)), (path, a, b)


def _pair(scenario="paper", **overrides):
    fast = parallel_env(scenario, **overrides)
    batched = parallel_env(scenario, **overrides)
    assert fast.sim.fast_path is not None
    batched.sim.fast_path = None  # the batched numpy step
    return fast, batched


def _fly(fast, batched, steps: int, seed: int, noise: float) -> int:
    """Step both envs alike with the consensus law on the route plus uniform noise, resetting
    at the end of an episode; returns the number of steps with an avoidance reference."""
    rng = np.random.default_rng(seed)
    _equal(fast.reset(seed=seed), batched.reset(seed=seed), "reset")
    u_max = fast.scenario.dynamics.u_max
    avoided = 0
    for k in range(steps):
        if not fast.agents:
            _equal(fast.reset(), batched.reset(), f"reset at {k}")
        last, sim = batched.sim.last, batched.sim
        # sim.offsets are the slots (the mirrored reading resolved by FormationConfig)
        u = consensus_pd(
            sim.z, last.reference_velocity, last.adjacency, sim.offsets, u_max
        )[0] / u_max  # fmt: skip
        u = u + noise * rng.uniform(-1.0, 1.0, u.shape)
        actions = {a: u[i].astype(np.float32) for i, a in enumerate(fast.agents)}
        for name, x, y in zip(_RETURNS, fast.step(actions), batched.step(actions)):
            _equal(x, y, f"step {k} {name}")
        for name in _SIM_STATE:
            _equal(getattr(fast.sim, name), getattr(batched.sim, name), f"step {k} sim.{name}")
        _equal(fast.state(), batched.state(), f"step {k} state")
        avoided += int(fast.sim.last.avoiding.any())
    return avoided


def test_paper_episode_is_the_batched_one_bit_for_bit() -> None:
    fast, batched = _pair()
    avoided = _fly(fast, batched, fast.scenario.n_steps + 5, seed=7, noise=0.3)
    assert avoided > 20  # the avoidance steps (batched topology update between the kernels)
    assert fast.sim.steps[0] == 5  # past a truncation and reset


@pytest.mark.parametrize(
    "scenario, overrides",
    [
        ("paper", {"observer__enabled": False}),
        ("paper", {"observer__estimate_without_s0": True, "observer__literal_sign_law": True}),
        ("paper", {"cost__obstacle": 2.0, "cost__obstacle_margin": 25.0}),
        ("paper", {"formation__mirrored_offsets": True, "disturbance__scalar_rand": True}),
        ("paper", {"observation__kind": "local", "observation__sensing_radius": 60.0}),
        ("paper", {"avoidance__rearm": True, "avoidance__reference_speed": "current"}),
        ("paper", {"disturbance__model": "none"}),
        ("paper", {"collision__obstacle_distance": 12.0}),
        (windy_scenario(), {}),
    ],
)
def test_other_scenarios_are_the_batched_ones(scenario, overrides) -> None:
    fast, batched = _pair(scenario, **overrides)
    assert _fly(fast, batched, 400, seed=3, noise=0.5) > 0


@pytest.mark.parametrize(
    "scenario, overrides",
    [
        ("random_fields", {}),
        ("paper", {"avoidance__turn_preview": 2.0}),
        ("paper", {"avoidance__route_gain": 0.1}),
    ],
)
def test_uncovered_features_take_the_batched_path(scenario, overrides) -> None:
    env = parallel_env(scenario, **overrides)
    assert env.sim.fast_path is None
    env.reset(seed=0)
    env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})


def test_numpy_sums_as_the_kernels_do() -> None:
    """The machine check that guards the fast path holds here (else the tests above would not
    run the kernels at all)."""
    assert fast_kernels.platform_agrees()


def test_without_numba_the_batched_path_runs(monkeypatch) -> None:
    monkeypatch.setattr(fast_step, "AVAILABLE", False)
    env = parallel_env("paper")
    assert env.sim.fast_path is None
    env.reset(seed=0)
    env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})


def test_an_unwritable_cache_compiles_without_it(monkeypatch) -> None:
    """numba refuses cache=True where it finds no writable cache directory: the kernels are
    then compiled for the process alone."""
    numba = fast_kernels.observer_kernel.numba
    compile_ = numba.njit
    calls = []

    def njit(*args, **kwargs):
        calls.append(kwargs)
        if kwargs.get("cache"):
            raise RuntimeError("cannot cache function: no locator available")
        return compile_(*args, **kwargs)

    monkeypatch.setattr(numba, "njit", njit)
    kernel = fast_kernels.njit(lambda x: x + 1.0)
    assert kernel(1.0) == 2.0
    assert calls == [{"cache": True}, {}]


def test_batches_with_autoreset_and_random_starts_are_the_batched_ones() -> None:
    """B = 3 copies (the kernels loop over copies), short episodes reset per copy, each episode
    started at a random step (flown there by a second simulator, then adopted)."""
    scenario = with_overrides(paper_scenario(), {"duration": 20.0, "episode.start": "random"})
    fast = FormationEpisodes(scenario, 3, autoreset=True)
    batched = FormationEpisodes(scenario, 3, autoreset=True)
    assert fast.sim.fast_path is not None
    batched.sim.fast_path = None
    rng = np.random.default_rng(5)
    _equal(fast.reset(seed=11), batched.reset(seed=11), "reset")
    resets = 0
    for k in range(250):
        actions = rng.uniform(-1.2, 1.2, (3, scenario.n_uav, 3))
        step = fast.step(actions)
        _equal(step, batched.step(actions), f"step {k}")
        for name in _SIM_STATE:
            _equal(getattr(fast.sim, name), getattr(batched.sim, name), f"step {k} sim.{name}")
        resets += int(step.done.sum())
    assert resets >= 3
