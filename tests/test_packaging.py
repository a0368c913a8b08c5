"""The wheel installs what the Python ecosystem expects, and nothing that clashes.

The wheel is built once per session, offline (``pip wheel --no-deps --no-build-isolation
--no-index``), from a copy of the sources in a temporary folder, so that the build leaves no
``build/`` or ``*.egg-info`` folder behind in the checkout.
"""

from __future__ import annotations

import email.message
import email.parser
import importlib.metadata
import os
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
# what the build reads: pyproject.toml names README.md (readme) and LICENSE (license-files)
BUILD_INPUTS = ("pyproject.toml", "README.md", "LICENSE", "uav_formation_env", "baselines")
# the repository folder -> the import name it installs under (pyproject.toml: package-dir)
INSTALLED_AS = {"uav_formation_env": "uav_formation_env", "baselines": "uav_formation_baselines"}
MIN_SETUPTOOLS = (77, 0)  # [build-system] requires: license-files and SPDX license expressions


def _setuptools_version() -> tuple[int, ...] | None:
    try:
        version = importlib.metadata.version("setuptools")
    except importlib.metadata.PackageNotFoundError:
        return None
    return tuple(int(part) for part in version.split(".")[:2] if part.isdigit())


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Iterator[zipfile.ZipFile]:
    """The project's wheel, built offline with the setuptools of this environment."""
    version = _setuptools_version()
    if version is None or version < MIN_SETUPTOOLS:
        pytest.skip(
            f"cannot build the wheel offline: needs setuptools >= "
            f"{'.'.join(map(str, MIN_SETUPTOOLS))} installed (no build isolation), found {version}"
        )
    source = tmp_path_factory.mktemp("source")
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in BUILD_INPUTS:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, source / name, ignore=ignore)
        else:
            shutil.copy2(path, source / name)
    out = tmp_path_factory.mktemp("wheel")
    command = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    command += ["--no-index", "--quiet", "--wheel-dir", str(out), str(source)]
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1")
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, f"pip wheel failed:\n{done.stdout}\n{done.stderr}"
    (built,) = out.glob("uav_formation_env-*.whl")
    with zipfile.ZipFile(built) as archive:
        yield archive


def _metadata(wheel: zipfile.ZipFile) -> email.message.Message:
    (name,) = [n for n in wheel.namelist() if n.endswith(".dist-info/METADATA")]
    return email.parser.Parser().parsestr(wheel.read(name).decode("utf-8"))


def test_wheel_has_no_top_level_baselines(wheel: zipfile.ZipFile):
    names = wheel.namelist()
    assert not [n for n in names if n.startswith("baselines/")]
    top_level = {n.split("/", 1)[0] for n in names if not n.split("/", 1)[0].endswith(".dist-info")}
    assert top_level == {"uav_formation_env", "uav_formation_baselines"}


def test_wheel_holds_packages_data_and_marker(wheel: zipfile.ZipFile):
    names = set(wheel.namelist())
    for required in (
        "uav_formation_baselines/__init__.py",
        "uav_formation_baselines/train.py",
        "uav_formation_baselines/hyperparams/ppo.yml",
        "uav_formation_baselines/hyperparams/sac.yml",
        "uav_formation_env/py.typed",
    ):
        assert required in names
    # every shipped model's files (package data under uav_formation_env/models/<name>/)
    models = ROOT / "uav_formation_env" / "models"
    for path in models.glob("*/*"):
        assert f"uav_formation_env/models/{path.relative_to(models).as_posix()}" in names
    # every module of the repository is installed: the package list in pyproject.toml is
    # explicit (package-dir needs it), so a new sub-package must be added there
    for folder, package in INSTALLED_AS.items():
        for path in (ROOT / folder).rglob("*.py"):
            installed = f"{package}/{path.relative_to(ROOT / folder).as_posix()}"
            assert installed in names, f"{installed} missing: add its package to pyproject.toml"


MAX_WHEEL_BYTES = 3_000_000  # 3 MB: the three shipped models are 1.8 MB of it


def test_wheel_is_small_and_ships_one_loadable_model_per_task(wheel: zipfile.ZipFile, tmp_path):
    assert Path(wheel.filename).stat().st_size <= MAX_WHEEL_BYTES
    names = wheel.namelist()
    # no file that loading would unpickle or run: TorchScript, pickles, SB3 archives
    assert not [n for n in names if n.endswith((".pt", ".pkl", ".zip", ".pth"))]
    shipped = sorted({n.split("/")[2] for n in names if n.startswith("uav_formation_env/models/")})
    assert shipped == ["paper_ppo", "random_fields_dagger", "random_swarm_dagger"]
    # installed from the wheel alone, a shipped model flies by name from anywhere
    target = tmp_path / "site"
    wheel.extractall(target)
    code = (
        "import sys; from uav_formation_env.cli import main; "
        "sys.exit(main(['evaluate', '--policy', 'paper_ppo', '--seeds', '1', "
        "'--duration', '2', '--quiet', '--out', 'out']))"
    )
    env = dict(os.environ, PYTHONPATH=str(target))
    done = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "summary.json").is_file()
    check = "import uav_formation_env, sys; print(uav_formation_env.__file__)"
    where = subprocess.run(
        [sys.executable, "-c", check], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert where.stdout.startswith(str(target))


def test_wheel_metadata(wheel: zipfile.ZipFile):
    metadata = _metadata(wheel)
    classifiers = metadata.get_all("Classifier") or []
    for minor in (10, 11, 12, 13):
        assert f"Programming Language :: Python :: 3.{minor}" in classifiers
    assert "Typing :: Typed" in classifiers
    licence = metadata.get("License-Expression") or metadata.get("License")
    assert licence == "MIT"
    assert "LICENSE" in (metadata.get_all("License-File") or [])
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in wheel.namelist())


def test_repository_files():
    for name in ("LICENSE", "CITATION.cff", "CHANGELOG.md"):
        assert (ROOT / name).is_file(), name
    assert "MIT License" in (ROOT / "LICENSE").read_text(encoding="utf-8")
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert str(citation["cff-version"]) == "1.2.0"
    assert citation["license"] == "MIT"
    # the version is written once: uav_formation_env.__version__ (pyproject.toml reads it)
    import uav_formation_env

    project = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert 'dynamic = ["version"]' in project and "uav_formation_env.__version__" in project
    assert "version" not in citation
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert "## [Unreleased]" in changelog
    assert f"## [{uav_formation_env.__version__}]" in changelog
