"""RL training throughput, ours beside peers measured in the same run (prints, asserts nothing).

The project's in-process trainer (``uav_formation_baselines.onpolicy``: PPO and MAPPO stepping the
batched episode layer under the training preset) is timed first, beside BenchMARL's MAPPO on VMAS
``navigation`` (5 agents, :mod:`bench_marl`'s settings) when vmas is importable; then SB3 PPO on
our VecEnv and on mpe2:

Both environments are SB3 VecEnvs with one entry per (copy, agent) and one shared policy:

* ours: :class:`~uav_formation_env.envs.vector.FormationVecEnv` on the paper scenario (N = 5,
  observer on, 1000-step episodes), ``--copies`` copies stepped as one batch;
* mpe2: ``simple_spread_v3.parallel_env(N=5, continuous_actions=True, max_cycles=1000)``,
  ``--copies`` separate ParallelEnvs behind a small VecEnv adapter written here (SuperSuit's
  wrappers fail with SB3 2.9 on ``PPO(..., seed=int)``), when mpe2 is importable.

The same PPO settings for both, the constructor arguments of ``baselines/hyperparams/ppo.yml``
(paper section), and one torch thread; the time is that of ``learn()``, rollouts and updates
together, on the bare VecEnvs. Rates are agent-timesteps/s (SB3's ``num_timesteps``, every entry
counts) and their ratio ours / mpe2, which is robust to the machine's speed. For information, our
full training stack (divergence reset, staggered start, monitor, VecNormalize) is timed too.

    python benchmarks/bench_rl.py [--timesteps 51200] [--copies 8] [--threads 1] [--updates 5]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

# uav_formation_baselines is the repository's baselines/ folder (installed by `pip install -e .`)
from uav_formation_baselines.config import load_hyperparams, split_params
from uav_formation_baselines.wrappers import make_training_env
from uav_formation_env import vec_env
from uav_formation_env.config_io import resolve_scenario


class ParallelCopiesVecEnv(VecEnv):
    """Several copies of a PettingZoo ParallelEnv as one SB3 VecEnv, one entry per (copy, agent).

    Entry ``b * N + i`` is agent i of copy b. A copy whose agents are all done is reset at once,
    with ``terminal_observation`` in the infos, as SB3 expects. Every agent must share one
    observation and one action space (parameter sharing).

    Args:
        make_env: builds one ParallelEnv.
        copies: number of copies.
    """

    def __init__(self, make_env: Callable[[], Any], copies: int) -> None:
        self.envs = [make_env() for _ in range(copies)]
        self.agents = list(self.envs[0].possible_agents)
        self.render_mode = None
        first = self.agents[0]
        super().__init__(
            copies * len(self.agents),
            self.envs[0].observation_space(first),
            self.envs[0].action_space(first),
        )
        self._seeds: list[int | None] = [None] * copies
        self._actions: np.ndarray | None = None

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        self._seeds = [None if seed is None else seed + b for b in range(len(self.envs))]
        return [s for s in self._seeds for _ in self.agents]

    def reset(self) -> np.ndarray:
        obs = [env.reset(seed=s)[0] for env, s in zip(self.envs, self._seeds)]
        self._seeds = [None] * len(self.envs)
        return np.stack([o[a] for o in obs for a in self.agents]).astype(np.float32)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32)

    def step_wait(self) -> VecEnvStepReturn:
        n = len(self.agents)
        obs_out, rewards, dones, infos = [], [], [], []
        for b, env in enumerate(self.envs):
            acts = {a: self._actions[b * n + i] for i, a in enumerate(self.agents)}
            obs, rew, term, trunc, _ = env.step(acts)
            done = all(term[a] or trunc[a] for a in self.agents)
            copy_obs = [obs[a] for a in self.agents]
            copy_infos: list[dict[str, Any]] = [{} for _ in self.agents]
            if done:
                for i, a in enumerate(self.agents):
                    copy_infos[i]["terminal_observation"] = copy_obs[i]
                    copy_infos[i]["TimeLimit.truncated"] = bool(trunc[a] and not term[a])
                fresh, _ = env.reset()
                copy_obs = [fresh[a] for a in self.agents]
            obs_out.extend(copy_obs)
            rewards.extend(rew[a] for a in self.agents)
            dones.extend([done] * n)
            infos.extend(copy_infos)
        return (
            np.stack(obs_out).astype(np.float32),
            np.asarray(rewards, dtype=np.float32),
            np.asarray(dones, dtype=bool),
            infos,
        )

    def close(self) -> None:
        for env in self.envs:
            env.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


def ppo_rate(
    venv: VecEnv, timesteps: int, settings: dict[str, Any], seed: int = 0
) -> tuple[float, int]:
    """(agent-timesteps/s of ``PPO.learn``, timesteps done) with PPO keyword ``settings``."""
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **settings)
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps)
    elapsed = time.perf_counter() - start
    return model.num_timesteps / elapsed, int(model.num_timesteps)


def mpe2_venv(copies: int) -> VecEnv | None:
    """``copies`` simple_spread_v3 envs (N = 5, continuous) as one VecEnv, or None."""
    try:
        from mpe2 import simple_spread_v3
    except ImportError:
        return None

    def make() -> Any:
        return simple_spread_v3.parallel_env(N=5, continuous_actions=True, max_cycles=1000)

    return ParallelCopiesVecEnv(make, copies)


def onpolicy_rate(algo: str, scenario: str, updates: int, threads: int) -> float:
    """Agent-steps/s of ``updates`` updates of the project's trainer (rollouts, updates and no
    evaluation) after one warm-up update, with ``baselines/hyperparams/onpolicy.yml``."""
    import tempfile

    from uav_formation_baselines.onpolicy_config import load_config
    from uav_formation_baselines.onpolicy_trainer import OnPolicyTrainer, build_scenario

    config = load_config(algo, {"eval_every": 0, "threads": threads})
    with tempfile.TemporaryDirectory() as folder:
        trainer = OnPolicyTrainer(algo, build_scenario(scenario, config), config, 0, 1, folder)
        trainer.rollout()
        trainer.update()
        start = time.perf_counter()
        for _ in range(updates):
            trainer.rollout()
            trainer.update()
        return updates * trainer.frames_per_update / (time.perf_counter() - start)


def vmas_mappo_rate(iterations: int) -> float | None:
    """Agent-steps/s of BenchMARL MAPPO on VMAS navigation (5 agents), or None without vmas."""
    from bench_marl import frames_per_second, vmas_navigation

    task = vmas_navigation(5)
    return None if task is None else 5 * frames_per_second("mappo", task, iterations)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument(
        "--timesteps",
        type=int,
        default=51200,
        help="agent-timesteps per env (rounded up to whole rollouts of n_steps x entries)",
    )
    parser.add_argument("--copies", type=int, default=8, help="copies of each 5-agent env")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--updates", type=int, default=5, help="updates of the in-process trainer")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    print("In-process trainer (onpolicy.yml, training preset), agent-steps/s:")
    rates = {
        algo: onpolicy_rate(algo, args.scenario, args.updates, args.threads)
        for algo in ("ppo", "mappo")
    }
    for algo, rate in rates.items():
        print(f"  ours {algo:5s} {args.scenario:>10s}            : {rate:>8,.0f}")
    vmas = vmas_mappo_rate(3)
    if vmas is None:
        print("  BenchMARL MAPPO VMAS navigation: skipped (vmas is not importable)")
    else:
        print(f"  BenchMARL MAPPO VMAS navigation    : {vmas:>8,.0f}")
        print(f"  ratio ours mappo / BenchMARL VMAS   : {rates['mappo'] / vmas:>8.3f}")
    training, settings = split_params(load_hyperparams("ppo", "paper"), PPO)
    training["copies"] = args.copies

    print(
        f"PPO (n_steps {settings['n_steps']}, batch {settings['batch_size']}, "
        f"{settings['n_epochs']} epochs, net {settings['policy_kwargs']['net_arch']}), "
        f"{args.copies} copies x 5 agents, {args.threads} torch thread(s); "
        "agent-timesteps/s of learn()"
    )
    venv = vec_env(args.scenario, num_copies=args.copies)
    ours, done = ppo_rate(venv, args.timesteps, settings)
    print(f"  uav_formation_v0 bare VecEnv       : {ours:>8,.0f}  ({done} steps)")
    stack, _ = make_training_env(resolve_scenario(args.scenario), training, settings["gamma"])
    full, done = ppo_rate(stack, args.timesteps, settings)
    print(f"  uav_formation_v0 training stack    : {full:>8,.0f}  ({done} steps, for information)")
    mpe_venv = mpe2_venv(args.copies)
    if mpe_venv is None:
        print("  mpe2 simple_spread_v3: skipped (mpe2 is not importable)")
        return
    mpe, done = ppo_rate(mpe_venv, args.timesteps, settings)
    print(f"  mpe2 simple_spread_v3 (continuous)  : {mpe:>8,.0f}  ({done} steps)")
    print(f"  ratio ours (bare) / mpe2            : {ours / mpe:>8.3f}")


if __name__ == "__main__":
    main()
