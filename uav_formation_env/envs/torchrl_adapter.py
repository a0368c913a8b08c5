"""A batched TorchRL ``EnvBase`` over the episode layer on the torch backend (issue 14).

:class:`FormationTorchRLEnv` steps B copies of a scenario as one tensor program: the simulator,
the cost and the observations run on torch (CPU or CUDA) through the same array-API core as
numpy; nothing goes through PettingZoo or numpy per step (the host only draws each copy's noise
blocks and scenes, see :mod:`uav_formation_env.sim`). Its specs are grouped the way TorchRL's
multi-agent wrappers (VMAS, PettingZoo) and BenchMARL expect:

| key | shape | dtype | meaning |
|---|---|---|---|
| ``("uav", "observation")`` | (B, N, dim) | float32 | each agent's observation (the scenario's layout) |
| ``("uav", "action")`` | (B, N, 3) | float32 | normalised input in [-1, 1] (``u_n = a · u_max``) |
| ``("uav", "reward")`` | (B, N, 1) | float32 | the episode layer's reward (-J_i through ``episode.reward``) |
| ``("uav", "info", "J")`` | (B, N, 1) | float32 | the raw stage cost J_i of the transition |
| ``"state"`` | (B, 12 N + 1 + N²) | float32 | the global state (``return_state=True``) |
| ``"done"``, ``"terminated"``, ``"truncated"`` | (B, 1) | bool | per copy (the episode layer's rules) |

Partial resets come as TorchRL's ``"_reset"`` mask (collectors send it for the copies that are
done); a copy's episode is named by its seed exactly as on numpy (``set_seed(s)`` gives copy b
the seed ``s + b`` at the next full reset, then each copy follows its own seed stream).
"""  # noqa: E501

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from uav_formation_env.config import Scenario
from uav_formation_env.episode import (
    EpisodeStep,
    FormationEpisodes,
    global_state,
    observation_bounds,
    observation_size,
)
from uav_formation_env.sim_options import SimOptions

__all__ = ["GROUP", "FormationTorchRLEnv"]

GROUP = "uav"  # the one agent group: every UAV shares the observation and action layout


class FormationTorchRLEnv(EnvBase):
    """B copies of ``scenario`` as a TorchRL environment on a torch device.

    Args:
        scenario: a validated scenario (see :func:`uav_formation_env.envs.torchrl_env`, which
            also takes names and overrides).
        num_envs: B, copies stepped together (the env's batch size).
        options: the simulator's :class:`~uav_formation_env.sim_options.SimOptions`, backend
            ``"torch"``; its device is that of every tensor (None: torch on the CPU).
        seed: seed of the first reset (None: fresh entropy).
        return_state: add the global state for centralised critics.
        n_uav: N of a scenario that draws N per reset.
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int = 1,
        options: SimOptions | None = None,
        seed: int | None = None,
        return_state: bool = True,
        n_uav: int | None = None,
    ) -> None:
        options = SimOptions(backend="torch") if options is None else options
        if options.backend != "torch":
            raise ValueError(f"options.backend must be 'torch', got {options.backend!r}")
        self.episodes = FormationEpisodes(scenario, num_envs, n_uav=n_uav, options=options)
        super().__init__(device=self.episodes.sim.device, batch_size=torch.Size([num_envs]))
        self.scenario = scenario
        self.n_agents = self.episodes.n_uav
        self.return_state = bool(return_state)
        self._next_seed = seed
        self._make_specs()

    def _make_specs(self) -> None:
        n, device = self.n_agents, self.device
        low, high = observation_bounds(self.scenario, n)
        dim = observation_size(self.scenario, n)
        observation = Bounded(
            low=torch.as_tensor(low, device=device).expand(n, dim),
            high=torch.as_tensor(high, device=device).expand(n, dim),
            shape=(n, dim),
            dtype=torch.float32,
            device=device,
        )
        group = Composite(
            {
                "observation": observation,
                "info": Composite(
                    {"J": Unbounded(shape=(n, 1), dtype=torch.float32, device=device)},
                    shape=(n,),
                ),
            },
            shape=(n,),
        )
        full_observation = Composite({GROUP: group}, device=device)
        if self.return_state:
            size = 12 * n + 1 + n * n
            full_observation["state"] = Unbounded(shape=(size,), dtype=torch.float32, device=device)
        self.full_observation_spec_unbatched = full_observation
        action = Bounded(low=-1.0, high=1.0, shape=(n, 3), dtype=torch.float32, device=device)
        self.full_action_spec_unbatched = Composite(
            {GROUP: Composite({"action": action}, shape=(n,))}, device=device
        )
        reward = Unbounded(shape=(n, 1), dtype=torch.float32, device=device)
        self.full_reward_spec_unbatched = Composite(
            {GROUP: Composite({"reward": reward}, shape=(n,))}, device=device
        )
        flag = Categorical(n=2, shape=(1,), dtype=torch.bool, device=device)
        self.full_done_spec_unbatched = Composite(
            {"done": flag, "terminated": flag.clone(), "truncated": flag.clone()}, device=device
        )

    @property
    def group_map(self) -> dict[str, list[str]]:
        """The one group of the N agents (TorchRL / BenchMARL ``group_map``)."""
        return {GROUP: [f"uav_{i}" for i in range(self.n_agents)]}

    # ------------------------------------------------------------------ EnvBase
    def _set_seed(self, seed: int | None) -> None:
        self._next_seed = seed

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None
        # .keys(): "in" on a TensorDict itself is not a key lookup
        if tensordict is not None and "_reset" in tensordict.keys():  # noqa: SIM118
            mask = tensordict.get("_reset").reshape(-1)
            if bool(mask.all()):
                mask = None
        if mask is not None and self.episodes.last is not None:
            step = self.episodes.reset(seed=None, mask=mask)
        else:
            seed, self._next_seed = self._next_seed, None
            step = self.episodes.reset(seed=seed)
        return self._output(step, with_reward=False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get((GROUP, "action"))
        step = self.episodes.step(actions)
        return self._output(step, with_reward=True)

    def _output(self, step: EpisodeStep, with_reward: bool) -> TensorDictBase:
        """The TensorDict of a reset or step (see the module docstring's table)."""
        n = self.n_agents
        group: dict[str, Any] = {
            "observation": step.observation,
            "info": TensorDict(
                {"J": step.cost.to(torch.float32).unsqueeze(-1)}, batch_size=(*self.batch_size, n)
            ),
        }
        if with_reward:
            group["reward"] = step.reward.to(torch.float32).unsqueeze(-1)
        done = (step.terminated | step.truncated).unsqueeze(-1)
        source: dict[str, Any] = {
            GROUP: TensorDict(group, batch_size=(*self.batch_size, n)),
            "done": done,
            "terminated": step.terminated.unsqueeze(-1),
            "truncated": step.truncated.unsqueeze(-1),
        }
        if self.return_state:
            source["state"] = global_state(self.episodes.sim, step.result)
        return TensorDict(source, batch_size=self.batch_size, device=self.device)
