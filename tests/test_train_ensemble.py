"""The DAgger ensemble recipe in one command (uav_formation_baselines.train_ensemble)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")

from uav_formation_baselines import train_ensemble as recipe  # noqa: E402
from uav_formation_baselines.config import parse_set  # noqa: E402
from uav_formation_baselines.ensemble import rank_runs  # noqa: E402
from uav_formation_baselines.imitation import load_config, train_imitation  # noqa: E402
from uav_formation_env.config_io import resolve_scenario, with_overrides  # noqa: E402
from uav_formation_env.episode import FormationEpisodes  # noqa: E402
from uav_formation_env.policies import make_policy  # noqa: E402
from uav_formation_env.policies.policy_file import load_policy_file  # noqa: E402

# students of seconds: 2 s episodes (10 steps), one epoch, an 8-unit layer, 2 validation seeds
TINY = [
    "rounds=2", "episodes=1", "duration=2.0", "hidden=[8]", "epochs=1", "validation_seeds=2",
    "start_episodes=1", "start_duration=0.4",
]  # fmt: skip
SHORT = with_overrides(
    resolve_scenario("paper"), {"duration": 2.0, "observation": {"kind": "local"}}
)


def _actions(path: Path, obs: np.ndarray) -> np.ndarray:
    return np.asarray(make_policy(str(path), SHORT).act_batch(obs))


def test_the_recipe_trains_each_seed_as_imitation_does_and_averages_the_best(
    tmp_path: Path,
) -> None:
    out = tmp_path / "ens"
    record = recipe.train_ensemble(
        "paper", out, runs=3, top=2, seed_start=5, workers=1, sets=TINY, progress=False
    )
    members = [out / "members" / f"seed_{s}" for s in (5, 6, 7)]
    assert record["recipe"]["seeds"] == [5, 6, 7]
    # the two best by validation, in rank order, and every student's steps counted
    best = [str(run) for run, _ in rank_runs(members)[:2]]
    assert [m["run"] for m in record["members"]] == best
    steps = [yaml.safe_load((m / "config.yaml").read_text())["agent_steps"] for m in members]
    assert record["recipe_agent_steps"] == sum(steps) > 0
    assert yaml.safe_load((out / "config.yaml").read_text())["recipe_wall_time_s"] > 0
    # a student is the run `imitation` trains for its seed with the recipe's settings
    config = load_config("paper", recipe.RECIPE, **parse_set(TINY))
    train_imitation("paper", tmp_path / "direct", config, seed=6, progress=False)
    obs = FormationEpisodes(SHORT, 2).reset(seed=[0, 1]).observation
    np.testing.assert_array_equal(_actions(members[1], obs), _actions(tmp_path / "direct", obs))
    # the ensemble's output is the mean of its members' (before act_batch bounds the action)
    flat = obs.reshape(-1, obs.shape[-1])
    mean = sum(load_policy_file(run).outputs(flat) for run in best) / 2
    np.testing.assert_allclose(load_policy_file(out).outputs(flat), mean, atol=1e-5)


def test_a_failing_student_stops_the_recipe_with_its_seed_and_last_line(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    def failing(scenario, out, seed, *rest):
        return [sys.executable, "-c", f"print('student {seed} is broken'); raise SystemExit(3)"]

    monkeypatch.setattr(recipe, "_student_command", failing)
    argv = ["--out", str(tmp_path / "ens"), "--runs", "2", "--workers", "1", "--quiet"]
    assert recipe.main([*argv, "--set", *TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("error: student seed ") and "(exit 3): student " in err[0]
    assert not (tmp_path / "ens" / "policy.json").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--runs", "0"], "error: runs must be an integer >= 1, got 0"),
        (["--runs", "2", "--top", "3"], "error: top must be at most runs (2), got 3"),
        (["--workers", "0"], "error: workers must be an integer >= 1, got 0"),
        (["--set", "round=2"], "error: unknown key 'round'"),
    ],
)
def test_bad_arguments_are_one_line_errors_before_any_student_starts(
    tmp_path: Path, capsys, args: list[str], message: str
) -> None:
    assert recipe.main(["--out", str(tmp_path / "ens"), "--quiet", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(message)
    assert not (tmp_path / "ens").exists()


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie waiting for its reaper does not)."""
    status = Path(f"/proc/{pid}/status")
    if not status.is_file():
        return False
    return "\nState:\tZ" not in status.read_text()


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads /proc (Linux)")
def test_a_failing_student_stops_the_processes_the_others_started(
    tmp_path: Path, monkeypatch
) -> None:
    marker = tmp_path / "worker.pid"

    def students(scenario, out, seed, *rest):
        if seed == 0:  # a student whose episode worker runs on
            code = (
                "import subprocess, sys, time\n"
                "w = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
                f"open({str(marker)!r}, 'w').write(str(w.pid)); time.sleep(120)"
            )
        else:  # fails once the other's worker is up
            code = (
                "import os, time\n"
                f"while not os.path.exists({str(marker)!r}): time.sleep(0.1)\n"
                "time.sleep(0.5); raise SystemExit('broken')"
            )
        return [sys.executable, "-c", code]

    monkeypatch.setattr(recipe, "_student_command", students)
    with pytest.raises(RuntimeError, match="student seed 1 failed"):
        recipe.train_ensemble("paper", tmp_path / "ens", runs=2, workers=1, sets=TINY,
                              progress=False)  # fmt: skip
    worker = int(marker.read_text())
    for _ in range(50):  # the kill is sent before train_ensemble returns; reaping may lag
        if not _alive(worker):
            break
        time.sleep(0.1)
    assert not _alive(worker)
