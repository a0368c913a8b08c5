"""The Ray backend: the same episodes, records and Table 2 as the local backend (local Ray, 2
CPUs)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import make_policy, run_episodes

ray = pytest.importorskip("ray", reason="the [ray] extra is not installed")

from uav_formation_env.distributed import chunks, ray_session, run_episodes_ray  # noqa: E402

SHORT = with_overrides(resolve_scenario("paper"), {"duration": 12.0})


@pytest.fixture(scope="module")
def local_ray():
    with ray_session(num_cpus=2) as session:
        yield session


def assert_same_episodes(a, b) -> None:
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if field.name in ("policy_seconds", "sim_seconds"):
            continue  # wall times
        if isinstance(x, dict):
            assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
        elif isinstance(x, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        else:
            assert x == y, field.name


def test_chunks() -> None:
    assert chunks([4, 5, 6, 7, 8], 2) == [[4, 5], [6, 7], [8]]
    with pytest.raises(ValueError, match="chunk_size"):
        chunks([1], 0)


@pytest.mark.parametrize("policy", ["lfpio", "random"])
def test_ray_evaluation_equals_the_local_one(local_ray, policy: str) -> None:
    seeds = [3, 4, 5]
    local = run_episodes(SHORT, make_policy(policy, SHORT), seeds, policy_name=policy)
    remote = run_episodes_ray(SHORT, policy, seeds, chunk_size=2, progress=False)
    assert remote.seeds == seeds
    assert_same_episodes(local, remote)


def test_reproduce_with_ray_writes_the_same_table2(local_ray, tmp_path: Path) -> None:
    from uav_formation_env.reproduce import reproduce

    kwargs = {"seeds": [0, 1], "duration": 8.0, "progress": False, "game_variants": []}
    reproduce(tmp_path / "local", jobs=1, **kwargs)
    reproduce(tmp_path / "ray", backend="ray", **kwargs)
    local = (tmp_path / "local" / "table2.csv").read_text()
    assert local == (tmp_path / "ray" / "table2.csv").read_text()


def test_cli_evaluate_with_ray_backend(local_ray, tmp_path: Path, capsys) -> None:
    from uav_formation_env.cli import main

    args = ["evaluate", "--policy", "heuristic", "--seeds", "2", "--duration", "8", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "l")]) == 0
    assert main([*args, "--backend", "ray", "--out", str(tmp_path / "r")]) == 0
    local = (tmp_path / "l" / "records.csv").read_text()
    assert local == (tmp_path / "r" / "records.csv").read_text()
    assert "mission completed" in capsys.readouterr().out
