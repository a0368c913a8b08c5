"""A new user's first hour: train, then evaluate the run directory; every trainer ends with the
held-out mission report (:mod:`uav_formation_env.evaluation.heldout`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from uav_formation_env.cli import TRAINERS, main
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides
from uav_formation_env.evaluation import make_policy, run_episodes, summarise
from uav_formation_env.evaluation.heldout import HELDOUT_FILE, heldout_report


def short_n3(duration: float = 4.0):
    return with_overrides(resolve_scenario("n3"), {"duration": duration})


# ------------------------------------------------------------------------------- heldout report
def test_heldout_report_is_the_evaluation_summary_and_a_policy_equals_itself() -> None:
    scenario = short_n3()
    policy = make_policy("heuristic", scenario)
    report = heldout_report(scenario, policy, [0, 1], policy_name="h", reference="heuristic")
    summary = summarise(run_episodes(scenario, make_policy("heuristic", scenario), [0, 1]))
    mission = summary["mission"]
    assert report.completed == mission["completed"] == report.reference_completed
    assert report.cost == pytest.approx(summary["realised_cost_mean"], rel=1e-12)
    assert report.cost_ratio == pytest.approx(1.0, rel=1e-12)  # the same policy on the same seeds
    assert report.route_error_max_m == max(mission["route_error_max_m_per_seed"])
    assert report.collisions_after_start == mission["collisions_after_start"]
    text = report.text()
    assert f"completed {report.completed} of 2" in text and "1 x HEURISTIC's" in text


def test_heldout_report_writes_json_and_needs_a_seed(tmp_path: Path) -> None:
    scenario = short_n3()
    report = heldout_report(
        scenario, make_policy("random", scenario, seed=0), [3], reference=None,
        training_reward=-12.5, out=tmp_path, duration=2.0,
    )  # fmt: skip
    data = json.loads((tmp_path / HELDOUT_FILE).read_text())
    assert data["seeds"] == [3] and data["duration_s"] == 2.0 and data["cost_ratio"] is None
    assert data["training_reward"] == -12.5 and "training reward" in report.text()
    with pytest.raises(ValueError, match="seeds"):
        heldout_report(scenario, make_policy("heuristic", scenario), [])


# ------------------------------------------------------------------------------- run directories
def test_a_directory_without_a_model_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    with pytest.raises(FileNotFoundError, match="holds no model"):
        make_policy(str(tmp_path), resolve_scenario("paper"))
    assert main(["evaluate", "--policy", str(tmp_path), "--out", str(tmp_path / "e")]) == 2
    assert "policy.json" in capsys.readouterr().err


def test_cli_train_then_evaluate_the_run_directory(tmp_path: Path, capsys) -> None:
    """``uav-formation train`` ends with the held-out mission; ``evaluate --policy DIR`` flies
    the directory it wrote."""
    pytest.importorskip("stable_baselines3")
    yaml_path = tmp_path / "n3_short.yaml"
    save_scenario(short_n3(), yaml_path)
    out = tmp_path / "run"
    code = main(
        [
            "train", "--algo", "ppo", "--timesteps", "384", "--out", str(out),
            "--scenario", str(yaml_path), "--copies", "2", "--no-progress", "--heldout-seeds", "2",
            "--set", "n_steps=32", "batch_size=64", "n_epochs=1", "eval_freq=0",
        ]
    )  # fmt: skip
    assert code == 0
    printed = capsys.readouterr().out
    assert "held-out mission" in printed and "completed" in printed and "LFPIO's" in printed
    heldout = json.loads((out / HELDOUT_FILE).read_text())
    assert heldout["seeds"] == [0, 1] and heldout["reference"] == "lfpio"
    evaluated = tmp_path / "eval"
    args = ["evaluate", "--policy", str(out), "--seeds", "1", "--quick", "--out", str(evaluated)]
    assert main([*args, "--quiet"]) == 0
    summary = json.loads((evaluated / "summary.json").read_text())
    assert summary["mission"]["episodes"] == 1 and summary["scenario"] == short_n3().name


# ------------------------------------------------------------------------------- train command
def test_train_is_a_command_of_its_own(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = capsys.readouterr().out
    assert text.startswith("usage: uav-formation train")
    assert "{ppo-fast,mappo,ippo,ppo,sac,rllib-ppo}" in text
    assert "(default: paper)" in text and " s " in text
    assert set(TRAINERS) >= {"ppo", "sac", "rllib-ppo"}


def test_rllib_without_its_venv_points_to_it_not_to_pip(tmp_path: Path, capsys) -> None:
    try:
        import ray.rllib  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("ray.rllib imports here: this is the RLlib venv")
    assert main(["train", "--algo", "rllib-ppo", "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert "tests/rllib/run.sh" in error and "pip install" not in error


# ------------------------------------------------------------------------------- smaller items
def test_progress_eta_counts_from_the_first_step_not_from_the_start_up() -> None:
    import io
    import time

    from tqdm import tqdm

    from uav_formation_env.reproduce.run import advance

    bar = tqdm(total=1000, file=io.StringIO(), mininterval=0.0)
    bar.start_t -= 3600.0  # an hour of start-up before the first step
    bar.last_print_t -= 3600.0
    advance(bar, 10)
    assert bar.n == 10 and bar.format_dict["elapsed"] < 60.0
    time.sleep(0.05)
    advance(bar, 10)
    assert bar.n == 20 and bar.format_dict["rate"] > 20.0  # steps/s: ETA in seconds, not hours
    bar.close()


def test_top_level_help_is_plain_text_with_every_policy(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "``" not in text and ":mod:" not in text
    assert "lfpio, pio, pso, exact, nash, heuristic, random" in text
    assert "run directory" in text and "Figs. 5-10" in text and "Figs. 5-9" not in text


def test_render_has_a_description_and_quick(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["render", "--help"])
    text = capsys.readouterr().out
    assert "top view" in text and "--quick" in text
    out = tmp_path / "episode.gif"
    args = ["render", "--policy", "heuristic", "--quick", "--every", "25", "--out", str(out)]
    assert main([*args, "--quiet"]) == 0
    from PIL import Image, ImageSequence

    with Image.open(out) as image:
        frames = sum(1 for _ in ImageSequence.Iterator(image))
    assert frames == 100 // 25 + 1  # 20 s of 0.2 s steps, one frame every 25 steps and the start


def test_shielded_evaluation_says_so_in_the_plot_title(tmp_path: Path, monkeypatch) -> None:
    import uav_formation_env.plotting as plotting

    titles = []
    real = plotting.plot_trajectories
    monkeypatch.setattr(
        plotting, "plot_trajectories", lambda *a, **k: titles.append(k["title"]) or real(*a, **k)
    )
    local = tmp_path / "local.yaml"
    save_scenario(with_overrides(short_n3(2.0), {"observation.kind": "local"}), local)
    args = ["evaluate", "--policy", "heuristic", "--scenario", str(local), "--seeds", "1"]
    assert main([*args, "--shield", "--out", str(tmp_path / "e"), "--quiet"]) == 0
    assert main([*args, "--out", str(tmp_path / "f"), "--quiet"]) == 0
    assert "safety shield" in titles[0] and "safety shield" not in titles[1]


# ------------------------------------------------------------------------------- README, docs
ROOT = Path(__file__).resolve().parents[1]


def _words(text: str) -> str:
    return " ".join(text.split())


def test_readme_durations_are_the_recorded_measurements() -> None:
    """Every duration the README gives is a row of docs/durations.md, and its minutes are that
    row's measured seconds: CPU time as "minutes of computing", wall time as "minutes measured"."""
    import re

    readme = _words((ROOT / "README.md").read_text(encoding="utf-8"))
    rows = re.findall(
        r"^\| ([\w-]+) \| ([^|]+) \| ([^|]+) \|", (ROOT / "docs" / "durations.md").read_text(),
        flags=re.M,
    )  # fmt: skip
    rows = {name: (says.strip(), measured) for name, says, measured in rows if name != "command"}
    assert set(rows) == {"main-command", "test-command", "shield-command"}
    for name, (says, measured) in rows.items():
        assert says in readme, name
        cpu = re.search(r"CPU (\d+) s", measured)
        wall = re.search(r"wall (\d+) s", measured)
        if cpu:
            assert f"about {round(int(cpu.group(1)) / 60)} minutes of computing" in says, name
        if wall:
            assert f"{round(int(wall.group(1)) / 60)} minutes measured" in says, name
    main_block = readme[readme.index("<!-- main-command -->") - 400 : readme.index("<!-- main")]
    assert rows["main-command"][0] in main_block  # said where the command is
    assert "about a minute" not in readme


def test_docs_index_lists_every_page_and_the_readme_links_it() -> None:
    index = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    for page in (ROOT / "docs").glob("*.md"):
        if page.name != "README.md":
            assert f"]({page.name})" in index, page.name
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "](docs/README.md)" in readme and "](docs/scenarios.md)" in readme


def test_first_use_block_runs_with_the_base_install(monkeypatch, tmp_path: Path) -> None:
    """The README's first Python block, right after the Quick start, needs no extra: it runs
    with stable-baselines3 and torch unimportable."""
    import re
    import sys

    for module in ("stable_baselines3", "torch"):
        monkeypatch.setitem(sys.modules, module, None)  # import raises ImportError
    monkeypatch.chdir(tmp_path)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    first = re.findall(r"```python\n(.*?)```", readme, flags=re.S)[0]
    exec(compile(first, "README.md python block 1", "exec"), {"__name__": "__readme__"})


def test_rllib_recipe_ends_with_the_heldout_report(tmp_path: Path, monkeypatch, capsys) -> None:
    """The RLlib recipe's end (its training needs the RLlib venv, replaced here by a run
    directory as it writes one): the held-out mission of its policy."""
    pytest.importorskip("torch")
    import numpy as np

    from uav_formation_baselines import rllib_ppo
    from uav_formation_baselines.torch_policy import NormalisedMLP, save_policy

    scenario = short_n3()

    def fake_train(args):
        dim = 33  # n3's full observation
        module = NormalisedMLP(np.zeros(dim), np.ones(dim), hidden=(8,))
        sample = np.zeros((2, dim), dtype=np.float32)
        save_policy(module, Path(args.out), sample, observation="full")
        save_scenario(scenario, Path(args.out) / "scenario.yaml")
        return {"returns": [float("nan"), -120.5]}

    monkeypatch.setattr(rllib_ppo, "train", fake_train)
    assert rllib_ppo.main(["--out", str(tmp_path), "--heldout-seeds", "1", "--quiet"]) == 0
    assert "held-out mission" in capsys.readouterr().out
    heldout = json.loads((tmp_path / HELDOUT_FILE).read_text())
    assert heldout["seeds"] == [0] and heldout["training_reward"] == -120.5
