"""Run folders are written whole or not at all (uav_formation_env.run_folder), for every command.

An earlier run survives a failed or interrupted one byte for byte; a successful one replaces it
whole (no stale file); a non-empty folder needs ``--overwrite`` and only a run's folder is
replaced; a folder that did not exist is not left behind empty.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uav_formation_env.cli import main
from uav_formation_env.run_folder import MARKER, atomic_file, check_out, run_folder


def earlier_run(folder: Path) -> dict[str, bytes]:
    """A folder as an earlier run leaves it; returns its files' bytes."""
    folder.mkdir(parents=True)
    files = {
        "summary.json": b'{"earlier": true}\n',
        "REPORT.md": b"# earlier\n",
        "records_n7.csv": b"a,b\n1,2\n",
        MARKER: b'{"command": "reproduce"}\n',
    }
    for name, data in files.items():
        (folder / name).write_bytes(data)
    return files


def contents(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def leftovers(parent: Path) -> list[str]:
    return [p.name for p in parent.iterdir() if ".partial-" in p.name or ".old-" in p.name]


def test_a_finished_run_replaces_the_earlier_one_whole(tmp_path):
    out = tmp_path / "run"
    earlier_run(out)
    with run_folder(out, overwrite=True, command="test") as partial:
        assert partial.parent == tmp_path and partial != out
        (partial / "summary.json").write_text("{}")
    assert sorted(contents(out)) == sorted([MARKER, "summary.json"])  # no stale records_n7.csv
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, RuntimeError])
def test_a_failed_or_interrupted_run_leaves_the_earlier_one_byte_identical(tmp_path, interrupt):
    out = tmp_path / "run"
    files = earlier_run(out)
    with pytest.raises(interrupt) as caught, run_folder(out, overwrite=True) as partial:
        (partial / "summary.json").write_text("{half")
        raise interrupt("stop")
    assert contents(out) == files
    assert leftovers(tmp_path) == []
    assert "earlier results are left whole" in caught.value.__notes__[0]


def test_a_failed_run_leaves_no_empty_folder(tmp_path):
    out = tmp_path / "a" / "b" / "run"
    with pytest.raises(RuntimeError), run_folder(out):
        raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("setup", "overwrite", "pattern"),
    [
        ("earlier", False, r"not empty .* --overwrite"),
        ("foreign", True, r"no uav-formation run wrote"),
        ("file", True, r"is a file"),
    ],
)
def test_out_is_refused(tmp_path, setup, overwrite, pattern):
    out = tmp_path / "run"
    if setup == "earlier":
        earlier_run(out)
    elif setup == "foreign":
        out.mkdir()
        (out / "thesis.tex").write_text("mine")
    else:
        out.write_text("a file")
    with pytest.raises(ValueError, match=pattern):
        check_out(out, overwrite)


def test_the_current_folder_is_never_a_run_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="current folder"):
        check_out(".", overwrite=True)


def test_atomic_file(tmp_path):
    out = tmp_path / "episode.gif"
    out.write_bytes(b"old")
    with pytest.raises(ValueError, match="--overwrite"), atomic_file(out):
        pass
    with pytest.raises(KeyboardInterrupt), atomic_file(out, overwrite=True) as partial:
        partial.write_bytes(b"half")
        raise KeyboardInterrupt
    assert out.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == [out.name]
    with atomic_file(out, overwrite=True) as partial:
        assert partial.suffix == ".gif"
        partial.write_bytes(b"new")
    assert out.read_bytes() == b"new"


def test_evaluate_replaces_an_earlier_run_only_with_overwrite(tmp_path, capsys):
    out = tmp_path / "eval"
    files = earlier_run(out)
    argv = ["evaluate", "--policy", "heuristic", "--seeds", "1", "--duration", "2", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--overwrite" in err[0]
    assert contents(out) == files
    assert main([*argv, "--out", str(out), "--overwrite"]) == 0
    written = sorted(contents(out))
    assert written == sorted([MARKER, "records.csv", "summary.json", "trajectories.png"])


def test_sigint_during_reproduce_leaves_the_earlier_run_byte_identical(tmp_path):
    """Ctrl-C while ``uav-formation reproduce --out D --overwrite`` writes its outputs over an
    earlier run: D keeps its files byte for byte, nothing partial remains, and the command says
    so."""
    out = tmp_path / "D"
    files = earlier_run(out)
    argv = ["reproduce", "--seeds", "1", "--quick", "--jobs", "1", "--quiet", "--overwrite"]
    process = subprocess.Popen(
        [sys.executable, "-m", "uav_formation_env.cli", *argv, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    # the moment the issue describes: the new table2.csv is written, the figures are not yet
    while not any(tmp_path.glob("*/table2.csv")) and not any(tmp_path.glob(".*/table2.csv")):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "interrupted" in err and "earlier results are left whole" in err
    assert contents(out) == files
    assert leftovers(tmp_path) == []
    assert os.listdir(tmp_path) == ["D"]


def test_sigint_during_train_saves_the_model_reached(tmp_path):
    """Ctrl-C during ``uav-formation train`` ends training, saves the model reached into --out
    (moved into place whole, ``interrupted: true`` in config.yaml) and exits with 130."""
    pytest.importorskip("stable_baselines3")
    import yaml

    out = tmp_path / "run"
    argv = [
        "train", "--algo", "ppo", "--timesteps", "100000000", "--out", str(out),
        "--scenario", "n3", "--copies", "1", "--no-progress",
        "--set", "n_steps=16", "batch_size=16", "n_epochs=1", "eval_freq=0", "checkpoint_freq=0",
    ]  # fmt: skip
    process = subprocess.Popen(
        [sys.executable, "-m", "uav_formation_env.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    # the first rollout is logged: training is under way
    while not any(p.stat().st_size for p in tmp_path.glob(".run.partial-*/progress.csv")):
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "interrupted at" in err
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["interrupted"] is True and 0 < config["timesteps"] < 100000000
    assert (out / "model.zip").stat().st_size > 0 and (out / "scenario.yaml").is_file()
    assert (out / MARKER).is_file() and leftovers(tmp_path) == []
