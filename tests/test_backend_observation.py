"""The observation encoders (core/observation.py, core/local_observation.py) on both backends.

numpy is the reference; torch (float64, on the CPU in CI, on CUDA when present) must give the same
observations and the same neighbour slots, ties included. Inputs: random arrays (with exact
distance ties, padded and absent obstacles, empty obstacle sets) and states recorded by stepping
the numpy sim of registered scenarios through ``episode.encode_observations``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uav_formation_env import episode as episode_module
from uav_formation_env.config import ObservationConfig
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.core import array_api
from uav_formation_env.core.local_observation import (
    _k_smallest,
    _neighbour_keys,
    build_local_observations,
)
from uav_formation_env.core.observation import build_observations
from uav_formation_env.core.proximity import SensedPairs, pair_distances, sensed_pairs

torch = pytest.importorskip("torch")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
TOL = {"rtol": 1e-12, "atol": 1e-12}


def on(x, device):
    """numpy arrays (and nested dict values) as torch tensors on ``device``; others unchanged."""
    if isinstance(x, dict):
        return {key: on(value, device) for key, value in x.items()}
    if isinstance(x, np.ndarray):
        return torch.as_tensor(np.array(x), device=device)  # a writable copy
    return x


def back(x):
    return array_api.to_numpy(x)


def assert_full_equal(kwargs, device):
    expected = build_observations(**kwargs)
    got = build_observations(**on(kwargs, device))
    assert got.dtype == torch.float32 and got.device.type == torch.device(device).type
    np.testing.assert_allclose(back(got), expected, **TOL)


def assert_local_equal(kwargs, device, torch_kwargs=None):
    expected = build_local_observations(**kwargs)
    got = build_local_observations(**(on(kwargs, device) if torch_kwargs is None else torch_kwargs))
    assert got.obs.dtype == torch.float32 and got.neighbour_index.dtype == torch.int64
    np.testing.assert_array_equal(back(got.neighbour_index), expected.neighbour_index)
    np.testing.assert_allclose(back(got.obs), expected.obs, **TOL)
    return expected


# ------------------------------------------------------------------------------------------------
# Shim additions
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("device", DEVICES)
def test_subtract_into_and_clip_in_place_write_views(device):
    rng = np.random.default_rng(0)
    x1, x2 = rng.normal(size=(3, 4)), rng.normal(size=(4,))
    low, high = -np.abs(rng.normal(size=4)) * 0.5, np.abs(rng.normal(size=4)) * 0.5
    results = []
    for make in (np.asarray, lambda a: torch.as_tensor(a, device=device)):
        out = make(np.zeros((3, 6)))
        array_api.subtract_into(out[:, 1:5], make(x1), make(x2))  # a view of out
        assert float(out[0, 0]) == 0.0 and float(out[0, 5]) == 0.0
        array_api.clip_in_place(out[:, 1:5], make(low), make(high))
        nan = make(np.array([np.nan, 5.0, -5.0]))
        array_api.clip_in_place(nan, -1.0, 1.0)
        results.append((back(out), back(nan)))
    (expected, expected_nan), (got, got_nan) = results
    np.testing.assert_array_equal(expected[:, 1:5], np.minimum(np.maximum(x1 - x2, low), high))
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got_nan, [np.nan, 1.0, -1.0])
    np.testing.assert_array_equal(expected_nan, [np.nan, 1.0, -1.0])


# ------------------------------------------------------------------------------------------------
# Random inputs
# ------------------------------------------------------------------------------------------------
def random_state(rng, batch, n_uav, grid):
    """(B, N, 6) states; ``grid``: integer positions, so that many distances tie exactly."""
    if grid:
        p = rng.integers(-3, 4, (batch, n_uav, 3)) * 10.0
        return np.concatenate((p, rng.normal(size=(batch, n_uav, 3))), -1)
    return rng.normal(size=(batch, n_uav, 6)) * [40, 40, 10, 5, 5, 1]


def random_obstacles(rng, batch, n_obs, grid):
    if grid:
        centres = rng.integers(-5, 6, (batch, n_obs, 2)) * 10.0
        radii = rng.integers(0, 3, (batch, n_obs)) * 5.0
    else:
        centres = rng.normal(size=(batch, n_obs, 2)) * 80
        radii = rng.uniform(1, 20, (batch, n_obs))
    return centres, radii


def random_common(rng, batch, n_uav, grid=False):
    z = random_state(rng, batch, n_uav, grid)
    return {
        "z": z,
        "reference_velocity": rng.normal(size=(batch, n_uav, 3)) * 5,
        "estimate": rng.normal(size=(batch, n_uav, 3)) * 0.2,
        "adjacency": (rng.random((batch, n_uav, n_uav)) < 0.4).astype(float),
        "avoiding": rng.random((batch, n_uav)) < 0.5,
        "time_fraction": rng.random(batch),
        "offsets": rng.normal(size=(n_uav, 6)) * [20, 20, 5, 1, 1, 0.2],
        "min_separation": rng.uniform(0, 2000, (batch, n_uav)),  # beyond the clip too
    }


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 4])
@pytest.mark.parametrize("n_uav", [2, 5, 9])
@pytest.mark.parametrize("obstacles", ["none", "shared", "per_copy"])
def test_full_observations_equal(device, batch, n_uav, obstacles):
    rng = np.random.default_rng(batch * 100 + n_uav)
    kwargs = random_common(rng, batch, n_uav, grid=obstacles == "per_copy")
    if obstacles == "none":
        kwargs["obstacle_centers"], kwargs["obstacle_radii"] = np.zeros((0, 2)), np.zeros(0)
    elif obstacles == "shared":
        centres, radii = random_obstacles(rng, 1, 3, False)
        kwargs["obstacle_centers"], kwargs["obstacle_radii"] = centres[0], radii[0]
    else:
        centres, radii = random_obstacles(rng, batch, 4, True)
        present = rng.random((batch, 4)) < 0.6
        present[0] = False  # a copy without obstacles: slots 14:18 are zeros
        if batch > 1:
            present[1] = True
            kwargs["offsets"] = rng.normal(size=(batch, n_uav, 6)) * 20  # per-copy formations
        centres[~present] = 1e9  # padding far away
        kwargs.update(obstacle_centers=centres, obstacle_radii=radii, obstacle_present=present)
    assert_full_equal(kwargs, device)


def local_kwargs(rng, batch, n_uav, n_obs, grid, **extra):
    kwargs = random_common(rng, batch, n_uav, grid)
    centres, radii = random_obstacles(rng, batch, n_obs, grid)
    kwargs.update(
        obstacle_centers=centres,
        obstacle_radii=radii,
        obstacle_present=rng.random((batch, n_obs)) < 0.7,
        next_velocity=rng.normal(size=(batch, 3)) * 5,
        time_to_switch=rng.uniform(0, 600, batch),
    )
    kwargs.update(extra)
    return kwargs


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch", [1, 3])
@pytest.mark.parametrize("n_uav", [1, 3, 6, 12])
@pytest.mark.parametrize("grid", [False, True])
@pytest.mark.parametrize("slots", [(4, 2, 2), (0, 0, 0), (2, 3, 0), (0, 1, 3), (15, 5, 4)])
def test_local_observations_equal(device, batch, n_uav, grid, slots):
    k, m, nearest = slots
    rng = np.random.default_rng(n_uav * 10 + batch + 1000 * grid)
    kwargs = local_kwargs(rng, batch, n_uav, 4, grid, k=k, m=m, nearest=nearest)
    assert_local_equal(kwargs, device)  # distance computed inside
    kwargs["distance"] = pair_distances(kwargs["z"][..., :3])
    assert_local_equal(kwargs, device)
    kwargs["sensing_radius"] = 35.0
    assert_local_equal(kwargs, device)


@pytest.mark.parametrize("device", DEVICES)
def test_local_edge_cases_equal(device):
    rng = np.random.default_rng(7)
    base = local_kwargs(rng, 3, 6, 3, True)
    cases = {
        "no obstacles": {
            "obstacle_centers": np.zeros((3, 0, 2)),
            "obstacle_radii": np.zeros((3, 0)),
            "obstacle_present": np.zeros((3, 0), dtype=bool),
        },
        "all absent": {"obstacle_present": np.zeros((3, 3), dtype=bool)},
        "all present": {"obstacle_present": np.ones((3, 3), dtype=bool)},
        "padding of any value": {
            "obstacle_centers": np.array([[[np.nan, 0.0], [np.inf, 1e12], [10.0, 0.0]]] * 3),
            "obstacle_present": np.array([[False, False, True]] * 3),
        },
        "no neighbours": {"adjacency": np.zeros((3, 6, 6))},
        "all neighbours": {"adjacency": np.ones((3, 6, 6))},
        "defaults": {"next_velocity": None, "time_to_switch": None},
        "everyone at one point": {"z": np.zeros((3, 6, 6))},
        "NaN distance": {"distance": np.where(np.eye(6, k=1, dtype=bool), np.nan, 5.0)[None]},
        "negative zero": {"distance": np.full((3, 6, 6), -0.0)},
    }
    for name, change in cases.items():
        kwargs = {**base, **change}
        if name.endswith("distance") or name == "negative zero":
            kwargs["distance"] = np.broadcast_to(kwargs["distance"], (3, 6, 6)).copy()
        assert_local_equal(kwargs, device), name


def test_negative_zero_distance_is_zero():
    """-0 and +0 distances give the same key (its bits would otherwise be the sign bit)."""
    distance = np.array([[[np.inf, -0.0, 0.0, 3.0]]])
    for neighbour in (True, False):
        mask = np.full(distance.shape, neighbour)
        keys = _neighbour_keys(distance, mask, np.zeros(distance.shape, dtype=bool))
        assert keys[0, 0, 1] == keys[0, 0, 2] < keys[0, 0, 3] < keys[0, 0, 0]


@pytest.mark.parametrize("device", DEVICES)
def test_k_smallest_ties_resolve_alike(device):
    """The numpy partial sort and torch's stable sort pick the same indices, ties included."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 5, 40):
        for keys in (
            rng.integers(0, 3, (50, n)),  # many ties
            rng.integers(-(2**62), 2**62, (50, n)),
            rng.uniform(0, 1, (50, n)).round(1),
        ):
            for k in range(0, n + 2):
                expected = _k_smallest(keys, k)
                got = _k_smallest(torch.as_tensor(keys, device=device), k)
                np.testing.assert_array_equal(back(got), expected)
                # the (key, index) order, spelled out
                order = np.lexsort((np.broadcast_to(np.arange(n), keys.shape), keys), axis=-1)
                np.testing.assert_array_equal(expected, order[:, :k])


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("device", DEVICES)
def test_numpy_mission_data_with_torch_states(device):
    """Offsets and obstacles may stay numpy (scenario data) when the states are tensors."""
    rng = np.random.default_rng(11)
    kwargs = local_kwargs(rng, 2, 5, 3, False)
    mixed = on(kwargs, device)
    for name in (
        "offsets",
        "obstacle_centers",
        "obstacle_radii",
        "obstacle_present",
        "time_fraction",
        "next_velocity",
        "time_to_switch",
    ):
        mixed[name] = kwargs[name]
    # read-only broadcast views, as the sim's shared obstacle field (no warning, no sharing)
    mixed["obstacle_present"] = np.broadcast_to(kwargs["obstacle_present"][:1], (2, 3))
    kwargs = {**kwargs, "obstacle_present": mixed["obstacle_present"]}
    assert_local_equal(kwargs, device, mixed)
    full = {key: kwargs[key] for key in random_common(rng, 1, 1)}
    full.update(obstacle_centers=kwargs["obstacle_centers"][0], obstacle_radii=np.ones(3))
    got = build_observations(
        **{**on(full, device), **{k: full[k] for k in ("offsets", "obstacle_centers")}}
    )
    np.testing.assert_allclose(back(got), build_observations(**full), **TOL)


def test_sensed_pairs_with_torch_states_are_refused():
    rng = np.random.default_rng(0)
    kwargs = local_kwargs(rng, 1, 6, 2, False)
    kwargs["distance"] = sensed_pairs(kwargs["z"][..., :3], 30.0)
    mixed = on(kwargs, "cpu")
    mixed["distance"] = kwargs["distance"]
    with pytest.raises(TypeError, match="sensed pairs .* numpy positions"):
        build_local_observations(**mixed)


# ------------------------------------------------------------------------------------------------
# States recorded from the numpy sim
# ------------------------------------------------------------------------------------------------
def recorded_calls(scenario, batch, seed, steps, monkeypatch, n_uav=None):
    """The keyword arguments ``episode.encode_observations`` hands to the builders, at reset and
    every ``steps[i]``-th step of a numpy sim flown by the consensus PD plus noise."""
    from uav_formation_env.policies.heuristic import consensus_pd
    from uav_formation_env.sim import FormationSim

    calls = []
    for name in ("build_observations", "build_local_observations"):
        real = getattr(episode_module, name)

        def capture(*args, _real=real, _name=name, **kwargs):
            calls.append((_name, args, kwargs))
            return _real(*args, **kwargs)

        monkeypatch.setattr(episode_module, name, capture)
    sim = FormationSim(scenario, batch, n_uav=n_uav)
    sim.fast_path = None  # the builders under test, not the compiled step's observation
    result = sim.reset(seed=seed)
    rng = np.random.default_rng(seed)
    episode_module.encode_observations(sim, result)
    for count in steps:
        for _ in range(count):
            last = sim.last
            u = consensus_pd(sim.z, last.reference_velocity, last.adjacency, sim.offsets, 5.0)
            result = sim.step(u + rng.normal(size=u.shape))
        episode_module.encode_observations(sim, result)
    return calls


def compare_call(name, args, kwargs, device):
    torch_args = [on(a, device) for a in args]
    torch_kwargs = on(kwargs, device)
    if name == "build_observations":
        expected = build_observations(*args, **kwargs)
        got = build_observations(*torch_args, **torch_kwargs)
        np.testing.assert_allclose(back(got), expected, **TOL)
        return
    if isinstance(kwargs["distance"], SensedPairs):  # torch takes the matrix and the radius
        torch_kwargs["distance"] = on(pair_distances(args[0][..., :3]), device)
        assert torch_kwargs["sensing_radius"] is not None
    expected = build_local_observations(*args, **kwargs)
    got = build_local_observations(*torch_args, **torch_kwargs)
    np.testing.assert_array_equal(back(got.neighbour_index), expected.neighbour_index)
    np.testing.assert_allclose(back(got.obs), expected.obs, **TOL)


def as_local(scenario):
    return dataclasses.replace(scenario, observation=ObservationConfig(kind="local"))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(
    ("name", "batch", "steps", "n_uav"),
    [
        # the paper's avoidance starts at step ~50 and its graph changes at ~50-70 and ~330-360
        ("paper", 2, (55, 20, 260, 30), None),
        ("paper-local", 2, (55, 20, 260, 30), None),
        ("random_swarm", 3, (55, 60), None),
        ("swarm_20", 2, (55, 20, 270), None),
        ("swarm_100", 1, (55,), None),  # N >= 64: the sim hands over sensed pairs
    ],
)
def test_recorded_sim_observations_equal(device, name, batch, steps, n_uav, monkeypatch):
    if name == "paper-local":
        scenario = as_local(resolve_scenario("paper"))
    elif name == "random_swarm":  # one N per simulator: drawn scenes of 7 UAVs
        scenario = with_overrides(resolve_scenario(name), {"scene__n_uav": [7, 7]})
    else:
        scenario = resolve_scenario(name)
    calls = recorded_calls(scenario, batch, 5, steps, monkeypatch, n_uav)
    assert len(calls) == len(steps) + 1
    if name.startswith("paper"):  # the states include avoidance references
        assert any(args[4].any() for _, args, _ in calls)
    for call in calls:
        compare_call(*call, device)
