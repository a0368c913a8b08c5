"""Score matrices for rliable from evaluation summaries (uav_formation_env.evaluation.export)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import make_policy, run_episodes, summarise
from uav_formation_env.evaluation.export import rliable_scores, write_rliable


def _summary(policy: str, scenario: str, seeds=(0, 1, 2)) -> dict:
    short = with_overrides(resolve_scenario(scenario), {"duration": 2.0})
    batch = run_episodes(short, make_policy(policy, short), list(seeds), policy_name=policy)
    return json.loads(json.dumps(summarise(batch), default=float))


def test_scores_are_seeds_by_tasks_with_higher_better(tmp_path):
    runs = {
        policy: [_summary(policy, "paper"), _summary(policy, "n3")]
        for policy in ("heuristic", "random")
    }
    (tmp_path / "h").mkdir()
    (tmp_path / "h" / "summary.json").write_text(json.dumps(runs["heuristic"][0]))
    runs["heuristic"][0] = tmp_path / "h"  # a folder of `uav-formation evaluate` works alike
    scores = rliable_scores(runs)
    assert set(scores) == {"heuristic", "random"}
    assert all(s.shape == (3, 2) for s in scores.values())
    expected = -np.asarray(
        json.loads((tmp_path / "h" / "summary.json").read_text())["realised_cost_per_seed"]
    )
    np.testing.assert_allclose(scores["heuristic"][:, 0], expected)
    assert (scores["heuristic"] > scores["random"]).all()  # the controller beats random actions
    completed = rliable_scores(runs, "completed")
    assert set(np.unique(completed["heuristic"])) <= {0.0, 1.0}
    loaded = dict(np.load(write_rliable(scores, tmp_path / "scores.npz")))
    np.testing.assert_array_equal(loaded["random"], scores["random"])


def test_runs_must_share_seeds_and_tasks():
    a, b = _summary("heuristic", "paper", (0, 1)), _summary("heuristic", "paper", (5, 6))
    with pytest.raises(ValueError, match="same seeds"):
        rliable_scores({"x": [a], "y": [b]})
    with pytest.raises(ValueError, match="same tasks"):
        rliable_scores({"x": [a, a], "y": [a]})
    with pytest.raises(ValueError, match="metric must be one of"):
        rliable_scores({"x": [a]}, "iqm")
