"""uav-formation-env: UAV formation control under disturbances and obstacles.

``parallel_env()`` / ``env()`` give the PettingZoo environment ``uav_formation_v0``;
``gymnasium.make("uav_formation_env/Formation-v0")`` the centralised single-agent view and
``gymnasium.make_vec("uav_formation_env/Formation-v0", num_envs=B)`` B batched copies of it (after
``import uav_formation_env``); ``uav_formation_env/FormationTrain-v0`` the same under the
training preset (:mod:`uav_formation_env.tasks`).
"""

from __future__ import annotations

import gymnasium

from uav_formation_env.envs import env, parallel_env, vec_env

__version__ = "0.1.0"

GYM_ID = "uav_formation_env/Formation-v0"
# the same view under the training preset (uav_formation_env.tasks): the learnable task
TRAIN_GYM_ID = "uav_formation_env/FormationTrain-v0"
for _id, _kwargs in ((GYM_ID, {}), (TRAIN_GYM_ID, {"reward": "train"})):
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="uav_formation_env.envs.gym_env:FormationGymEnv",
            vector_entry_point="uav_formation_env.envs.gym_vector:FormationVectorEnv",
            kwargs=_kwargs,
        )


def _preload_in_forkserver() -> None:
    """Import this package in multiprocessing's fork server, so that workers forked from it
    (SB3's ``SubprocVecEnv``, Gymnasium's ``AsyncVectorEnv`` on Linux) know ``GYM_ID`` even
    when ``__main__`` does not import it (``python -c``, notebooks, pytest). Appends to the
    preload list; no effect once the fork server runs, or where there is none."""
    try:
        from multiprocessing import forkserver

        preload = list(getattr(forkserver._forkserver, "_preload_modules", ["__main__"]))
        if __name__ not in preload:
            forkserver.set_forkserver_preload([*preload, __name__])
    except (ImportError, AttributeError, ValueError):  # no fork server on this platform
        pass


_preload_in_forkserver()

__all__ = ["GYM_ID", "TRAIN_GYM_ID", "__version__", "env", "parallel_env", "vec_env"]
