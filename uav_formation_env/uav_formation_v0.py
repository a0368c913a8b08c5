"""The PettingZoo module of the environment, as MPE2's ``simple_spread_v3``: ``env`` (AEC),
``parallel_env`` and ``raw_env``, so that ``from uav_formation_env import uav_formation_v0``
works where PettingZoo tools expect an environment module
(``pettingzoo.test.max_cycles_test(uav_formation_v0)``). Every function takes the arguments of
:func:`uav_formation_env.parallel_env`, ``max_cycles`` among them."""

from uav_formation_env.envs import env, parallel_env

raw_env = env  # the AEC env; it needs none of PettingZoo's wrappers (it checks actions itself)

__all__ = ["env", "parallel_env", "raw_env"]
