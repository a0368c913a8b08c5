"""uav-formation-env: UAV formation control under disturbances and obstacles.

``parallel_env()`` / ``env()`` give the PettingZoo environment ``uav_formation_v0``;
``gymnasium.make("uav_formation_env/Formation-v0")`` the centralised single-agent view and
``gymnasium.make_vec("uav_formation_env/Formation-v0", num_envs=B)`` B batched copies of it (after
``import uav_formation_env``).
"""

from __future__ import annotations

import gymnasium

from uav_formation_env.envs import env, parallel_env, vec_env

__version__ = "0.1.0"

GYM_ID = "uav_formation_env/Formation-v0"
if GYM_ID not in gymnasium.registry:
    gymnasium.register(
        id=GYM_ID,
        entry_point="uav_formation_env.envs.gym_env:FormationGymEnv",
        vector_entry_point="uav_formation_env.envs.gym_vector:FormationVectorEnv",
    )

__all__ = ["GYM_ID", "__version__", "env", "parallel_env", "vec_env"]
