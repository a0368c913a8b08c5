"""The documentation the code cites exists: every cited section of docs/model.md has a heading."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MODEL_MD = ROOT / "docs" / "model.md"
# the package's sources (the env and the RL baselines, installed as uav_formation_baselines),
# and the tests and benchmarks, which cite the same sections
SOURCES = (ROOT / "uav_formation_env", ROOT / "baselines", ROOT / "tests", ROOT / "benchmarks")

SECTION = r"§(\d+[a-z]?(?:\.\d+)*)"
# "docs/model.md §4.3" or, until the docstrings are switched over, "SPEC §4.3" / "SPEC.md §8",
# with the sections listed after it: "SPEC §1.4, §3.3, §3.4, §7", "SPEC.md §8 and §9b"
CITATION = re.compile(
    rf"(?:docs/model\.md|\bSPEC(?:\.md)?) ?{SECTION}((?:(?:,\s*|\s+and\s+|\s*/\s*){SECTION})*)"
)
HEADING = re.compile(rf"^#{{1,6}}\s+{SECTION}\s", re.MULTILINE)


def cited_sections() -> dict[str, list[str]]:
    """Section -> the places (``path:line``) that cite it."""
    cited: dict[str, list[str]] = {}
    for folder in SOURCES:
        for path in sorted(folder.rglob("*.py")):
            if path.resolve() == Path(__file__).resolve():
                continue  # this file's examples
            text = path.read_text(encoding="utf-8")
            for match in CITATION.finditer(text):
                line = text.count("\n", 0, match.start()) + 1
                where = f"{path.relative_to(ROOT)}:{line}"
                sections = [match.group(1), *re.findall(SECTION, match.group(2))]
                for section in sections:
                    cited.setdefault(section, []).append(where)
    return cited


def model_headings() -> set[str]:
    return set(HEADING.findall(MODEL_MD.read_text(encoding="utf-8")))


def test_citation_pattern():
    text = "x (SPEC §1.4, §3.3 and §9b) y SPEC.md §8. docs/model.md §4.3 docs/deviations.md §6"
    found = [[m.group(1), *re.findall(SECTION, m.group(2))] for m in CITATION.finditer(text)]
    assert found == [["1.4", "3.3", "9b"], ["8"], ["4.3"]]


def test_model_md_covers_every_cited_section():
    cited = cited_sections()
    assert len(cited) >= 10, f"expected many cited sections, found {sorted(cited)}"
    headings = model_headings()
    missing = {section: places for section, places in cited.items() if section not in headings}
    assert not missing, (
        "sections cited in the code without a heading in docs/model.md: "
        + "; ".join(f"§{s} ({', '.join(p[:3])})" for s, p in sorted(missing.items()))
    )
