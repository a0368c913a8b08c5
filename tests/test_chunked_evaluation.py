"""Seeds flown in chunks: the merged summary equals the summary of one batch of every seed, and
the per-step records equal those of one batch (``uav-formation evaluate --batch-size``)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from uav_formation_env.cli import main as cli_main
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import (
    fly_in_chunks,
    make_policy,
    run_episode_groups,
    summarise_digests,
    summarise_groups,
)

# wall times differ between runs; everything else must not
TIMINGS = {
    "wall_time_per_step_s",
    "wall_time_per_step_per_episode_s",
    "policy_time_per_step_s",
    "seconds_per_batch",
    "seconds_per_episode",
}


def assert_same(got, want, where: str = "summary") -> None:
    """Equal JSON-like trees, floats to 1e-9 relative (means of the same numbers, summed in
    another order)."""
    if isinstance(want, dict):
        assert set(got) == set(want), f"{where}: keys {set(got) ^ set(want)}"
        for key in want:
            if key not in TIMINGS:
                assert_same(got[key], want[key], f"{where}.{key}")
    elif isinstance(want, list | tuple):
        assert len(got) == len(want), where
        for k, (a, b) in enumerate(zip(got, want, strict=True)):
            assert_same(a, b, f"{where}[{k}]")
    elif isinstance(want, float) and not isinstance(got, bool):
        assert math.isclose(got, want, rel_tol=1e-9, abs_tol=1e-12) or (
            math.isnan(got) and math.isnan(want)
        ), f"{where}: {got} != {want}"
    else:
        assert got == want, f"{where}: {got!r} != {want!r}"


@pytest.mark.parametrize(
    ("name", "policy", "duration", "seeds"),
    [
        ("paper", "heuristic", 20.0, [0, 1, 2, 3, 4]),
        ("paper", "lfpio", 4.0, [0, 1, 2]),  # triggers and optimiser ratios
        ("random_swarm", "heuristic", 40.0, [0, 1, 2, 3, 4, 5]),  # several N
    ],
)
def test_chunks_merge_into_the_summary_of_one_batch(name, policy, duration, seeds):
    scenario = with_overrides(resolve_scenario(name), {"duration": duration})
    flyer = make_policy(policy, scenario)
    whole = summarise_groups(run_episode_groups(scenario, flyer, seeds, progress=False))
    chunks = fly_in_chunks(scenario, flyer, seeds, 2, progress=False)
    assert max(len(c.summary["seeds"]) for c in chunks) <= 2 and len(chunks) >= 2
    assert_same(summarise_digests(chunks), whole)


def test_evaluate_in_chunks_writes_the_records_of_one_batch(tmp_path: Path):
    argv = ["evaluate", "--policy", "heuristic", "--seeds", "3", "--duration", "4", "--quiet"]
    assert cli_main([*argv, "--out", str(tmp_path / "whole")]) == 0
    assert cli_main([*argv, "--batch-size", "1", "--out", str(tmp_path / "chunks")]) == 0
    whole, chunks = (tmp_path / d / "records.csv" for d in ("whole", "chunks"))
    assert chunks.read_text() == whole.read_text()


def test_chunk_size_must_be_positive():
    scenario = resolve_scenario("paper")
    with pytest.raises(ValueError, match="chunk_size must be >= 1, got 0"):
        fly_in_chunks(scenario, make_policy("heuristic", scenario), [0], 0)
