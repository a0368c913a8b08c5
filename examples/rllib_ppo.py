"""RLlib (new API stack) PPO on the paper's scenario, one policy shared by the five UAVs.

The recipe lives in :mod:`uav_formation_baselines.rllib_ppo` (also ``uav-formation train --algo
rllib-ppo``); this example runs it. RLlib needs its own virtual environment (``ray[rllib]`` 2.60
pins gymnasium 1.2.2); ``bash tests/rllib/run.sh`` builds one. By hand::

    python -m venv .venv-rllib && . .venv-rllib/bin/activate
    pip install torch==2.13.0 && pip install -e ".[rllib]"
    python examples/rllib_ppo.py --iterations 20 --num-env-runners 2 --out runs/rllib
    python examples/rllib_ppo.py --quick --out /tmp/rllib     # one tiny iteration
    uav-formation evaluate --policy runs/rllib --seeds 5   # in any environment, numpy alone
"""

from __future__ import annotations

from uav_formation_baselines.rllib_ppo import main

if __name__ == "__main__":
    raise SystemExit(main())
