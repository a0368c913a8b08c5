"""tests/rllib runs in its own virtual environment (tests/rllib/run.sh): ``ray[rllib]`` pins a
gymnasium older than the main environment's. Where ray is not installed (the main test run) this
folder is not collected at all."""

from __future__ import annotations

import importlib.util

collect_ignore_glob = [] if importlib.util.find_spec("ray") is not None else ["*.py"]
