"""The records baselines/RESULTS.md cites: one folder, a manifest that names each file's command,
commit, sha256 and figures, and a results page that opens with its leaderboard."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
RECORDS = ROOT / "baselines" / "records"
RESULTS = ROOT / "baselines" / "RESULTS.md"


def _manifest() -> list[dict]:
    return yaml.safe_load((RECORDS / "manifest.yaml").read_text(encoding="utf-8"))["records"]


def test_every_record_is_in_the_manifest_with_its_checksum() -> None:
    entries = _manifest()
    files = sorted(
        p.relative_to(RECORDS).as_posix()
        for p in RECORDS.rglob("*")
        if p.is_file() and p.name != "manifest.yaml"
    )
    assert sorted(e["path"] for e in entries) == files
    assert len(files) + 1 <= 60  # tracked record files, the manifest included
    for entry in entries:
        assert entry["command"].strip() and entry["figures"], entry["path"]
        assert re.fullmatch(r"[0-9a-f]{7,40}", entry["commit"]), entry["path"]
        digest = hashlib.sha256((RECORDS / entry["path"]).read_bytes()).hexdigest()
        assert digest == entry["sha256"], f"{entry['path']} changed since the manifest"


def test_results_cite_only_records_that_exist_and_every_record_is_cited() -> None:
    text = RESULTS.read_text(encoding="utf-8")
    links = re.findall(r"\]\((records/[^)#]*)\)", text)
    assert links
    for link in links:
        assert (ROOT / "baselines" / link).exists(), link
    cited = {link.split("/")[1] for link in links if link.count("/") >= 1 and link != "records/"}
    folders = {p.name for p in RECORDS.iterdir() if p.is_dir()}
    assert folders <= cited, f"records nothing cites: {sorted(folders - cited)}"
    assert not (ROOT / "baselines" / "eval_results").exists()


def test_results_open_with_the_leaderboard() -> None:
    lines = RESULTS.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 400
    header = next(i for i, line in enumerate(lines) if line.startswith("| policy |"))
    assert header < 25
    assert lines[header].split("|")[2:6] == [
        " paper ",
        " `random_fields` ",
        " `random_swarm` ",
        " `swarm_20` ",
    ]
    rows = {line.split("|")[1].strip() for line in lines[header + 2 :] if line.startswith("|")}
    for policy in ("LFPIO", "PIO", "exact", "Nash", "PSO", "heuristic", "DAgger", "MAPPO", "SAC"):
        assert any(policy in row for row in rows), policy
    findings = [line for line in lines if re.match(r"\d\. ", line)]
    assert 1 <= len(findings) <= 5
    assert not re.search(r"\bstop \d+", "\n".join(lines))
    assert "## Reinforcement learning from the training reward" in lines
