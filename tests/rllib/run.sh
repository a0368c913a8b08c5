#!/usr/bin/env bash
# The RLlib smoke test, in its own virtual environment: ray[rllib] 2.60 pins gymnasium 1.2.2,
# the main environment has gymnasium 1.4, so RLlib cannot share the main test venv.
#
#   bash tests/rllib/run.sh                 # CI calls it after the main test suite
#   UAV_RLLIB_VENV=/tmp/v bash tests/rllib/run.sh
#
# Creates the venv (default .venv-rllib in the checkout, git-ignored) from scratch if it is missing or broken; reuses it
# as it is when this same script completed it for this same checkout and pyproject.toml (a stamp
# file holds their hash); otherwise installs torch 2.13.0 first (the CPU build, not several GB of
# CUDA packages), then this checkout (editable) with its [rllib] extra and pytest. Then runs
# tests/rllib with that venv's python.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="${UAV_RLLIB_VENV:-$root/.venv-rllib}"
python_cmd="${UAV_RLLIB_PYTHON:-python3}"
# used only if pyproject.toml does not (yet) define the [rllib] extra
ray_spec="ray[rllib]==2.60.0"
torch_spec="torch==2.13.0"
stamp="$venv/.uav-rllib-complete"
start=$(date +%s)

# the venv's editable install must point at this checkout (CI tests a fresh clone)
fingerprint=$( (echo "$root" && cat "$0" "$root/pyproject.toml") | sha256sum | cut -d' ' -f1)

complete() {
  [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$fingerprint" ] &&
    "$venv/bin/python" -c "import ray.rllib, torch, pytest, uav_formation_env" 2>/dev/null
}

if complete; then
  echo "+ reusing $venv"
else
  if ! "$venv/bin/python" -c "import sys" 2>/dev/null; then
    echo "+ creating $venv"
    rm -rf "$venv"
    "$python_cmd" -m venv "$venv"
  else
    echo "+ completing $venv"
  fi
  rm -f "$stamp"
  pip=("$venv/bin/python" -m pip install --quiet)
  echo "+ pip install $torch_spec"
  "${pip[@]}" "$torch_spec"
  echo "+ pip install -e \"$root[rllib]\" pytest"
  "${pip[@]}" -e "$root[rllib]" pytest
  if ! "$venv/bin/python" -c "import ray.rllib" 2>/dev/null; then
    echo "+ no [rllib] extra in pyproject.toml: pip install $ray_spec"
    "${pip[@]}" "$ray_spec"
  fi
  "$venv/bin/python" -c "import ray.rllib, torch, pytest, uav_formation_env"
  echo "$fingerprint" >"$stamp"
fi
"$venv/bin/python" -c "import ray, torch, gymnasium, pettingzoo; print('+ ray', ray.__version__,
  '| torch', torch.__version__, '| gymnasium', gymnasium.__version__,
  '| pettingzoo', pettingzoo.__version__)"

cd "$root"
echo "+ python -m pytest tests/rllib (setup took $(($(date +%s) - start)) s)"
# RAY_AUTH_MODE: no token file for a throwaway local cluster; no usage stats either
RAY_AUTH_MODE=disabled RAY_USAGE_STATS_ENABLED=0 \
  "$venv/bin/python" -m pytest -q -p no:cacheprovider -o addopts=-ra tests/rllib
