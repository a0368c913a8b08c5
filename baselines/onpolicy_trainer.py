"""The on-policy trainer's loop: rollouts of the batched episode layer into preallocated
buffers, GAE with bootstrapped truncation, clipped-surrogate updates over (step, copy, agent)
rows, evaluations on held-out seeds and saves (:mod:`uav_formation_baselines.onpolicy` is its
command line).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import sys
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

from uav_formation_baselines.onpolicy_config import ONPOLICY_ALGOS, OnPolicyConfig
from uav_formation_baselines.onpolicy_io import (
    atomic_write,
    export_policy,
    load_actor,
    policy_architecture,
    read_policy,
)
from uav_formation_baselines.onpolicy_nets import ActorCritic, RunningNorm, TorchActorPolicy
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, save_scenario, with_overrides
from uav_formation_env.core.local_observation import observation_size
from uav_formation_env.episode import FormationEpisodes, global_state
from uav_formation_env.evaluation import run_episode_groups, summarise_groups
from uav_formation_env.policies.action_modes import VelocitySetpointPolicy
from uav_formation_env.scenes import n_uav_range
from uav_formation_env.sim_options import SimOptions
from uav_formation_env.tasks import evaluation_scenario, training_scenario

TRAIN_SEED_BASE = 1_000_000  # training copies' first seeds: seed * BASE + BASE + b
PROGRESS_COLUMNS = (
    "update", "frames", "wall_s", "cpu_s", "fps", "mean_reward", "mean_return", "mean_length",
    "episodes",
    "task", "eval_return",
    "eval_completed", "eval_episodes", "eval_route_error_max_m", "eval_collisions", "eval_J",
)  # fmt: skip


def gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    next_value: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimates and returns.

    Args:
        rewards, values: (T, ...) per step; a truncated step's reward already holds
            ``gamma V(final observation)`` (:func:`bootstrap_truncated`).
        dones: (T, ...) 1.0 where the episode ended after step t (terminated or truncated).
        next_value: (...) value of the observation after the last step.

    Returns:
        ``(advantages, returns)``, each (T, ...), ``returns = advantages + values``.
    """
    advantages = torch.zeros_like(rewards)
    last = torch.zeros_like(next_value)
    for t in reversed(range(rewards.shape[0])):
        following = next_value if t == rewards.shape[0] - 1 else values[t + 1]
        live = 1.0 - dones[t]
        delta = rewards[t] + gamma * following * live - values[t]
        last = delta + gamma * lam * live * last
        advantages[t] = last
    return advantages, advantages + values


def bootstrap_truncated(
    reward: torch.Tensor, final_value: torch.Tensor, truncated: torch.Tensor, gamma: float
) -> torch.Tensor:
    """(B, N) rewards with ``gamma V(final)`` added in the copies ``truncated`` (B,) bool: a
    time-limit or divergence end is not the end of the task's return (terminated: no value)."""
    return reward + gamma * final_value * truncated[:, None].to(final_value.dtype)


def build_scenario(task: str | Path | Scenario, config: OnPolicyConfig) -> Scenario:
    """The training scenario: the task, under the training preset unless ``reward`` is
    ``"paper"`` (:func:`uav_formation_env.tasks.training_scenario`), then ``config.env``."""
    scenario = resolve_scenario(task)
    if config.reward == "train":
        scenario = training_scenario(scenario)
    if config.env:
        scenario = with_overrides(scenario, config.env)
    return scenario


class OnPolicyTrainer:
    """One run: episodes, actor-critic, rollout buffers, updates, evaluations and saves.

    Args:
        algo: ``"ppo"``, ``"mappo"`` or ``"ippo"``.
        scenario: the training scenario (:func:`build_scenario`).
        config: hyper-parameters.
        seed: seeds torch and the training copies.
        frames: agent-steps to train for (rounded up to whole updates).
        out: run directory (created).
        device: ``"cpu"`` (numpy episode layer) or a CUDA device (torch episode layer).
        init: a run directory to start from (its ``checkpoint.pt``: actor, critic and
            normalisers), or a policy directory (``policy.json`` + ``policy.npz``: the actor and
            its observation statistics, whose architecture replaces ``hidden``, ``activation``
            and ``obs_clip``), or None.
        backend: the episode layer's array library (None: numpy on the CPU, torch elsewhere).
        resume: continue the run saved in ``out`` (its ``checkpoint.pt``: networks, optimiser,
            frames, update, times) up to ``frames``, appending to its ``progress.csv``; the
            episodes start afresh.
        ladder: the curriculum's next tasks (same observation size as ``scenario``): after an
            evaluation that completes ``config.promote_at`` of its missions the copies move to
            the next one (:meth:`promote`).
        init_member: with a policy directory of several networks (an ensemble), the one to
            start from.
    """

    def __init__(
        self,
        algo: str,
        scenario: Scenario,
        config: OnPolicyConfig,
        seed: int,
        frames: int,
        out: str | Path,
        device: str = "cpu",
        init: str | Path | None = None,
        backend: str | None = None,
        resume: bool = False,
        ladder: Sequence[Scenario] | None = None,
        init_member: int | None = None,
    ) -> None:
        if algo not in ONPOLICY_ALGOS:
            raise ValueError(f"algo must be one of {ONPOLICY_ALGOS}, got {algo!r}")
        sizes = {observation_size(task) for task in (scenario, *(ladder or ()))}
        if len(sizes) > 1:
            names = [task.name for task in (scenario, *(ladder or ()))]
            raise ValueError(f"a curriculum needs one observation size; {names} give {sizes}")
        for task in (scenario, *(ladder or ())):
            low, high = n_uav_range(task)
            if algo != "ppo" and low != high:
                why = "one network per UAV" if algo == "ippo" else "a critic on the global state"
                raise ValueError(
                    f"{algo} needs a fixed number of UAVs ({why}); scenario {task.name!r} draws "
                    f"N in {low}..{high}: use ppo (one group of copies per N)"
                )
        if resume and init is not None:
            raise ValueError("resume continues the run in out; it takes no --init")
        if config.init_reg > 0 and init is None:
            raise ValueError("init_reg pulls the actor towards its --init weights: give --init")
        self.init = "" if init is None else str(init)
        self.init_member = init_member
        policy_file = None
        if init_member is not None and (init is None or (Path(init) / "checkpoint.pt").is_file()):
            raise ValueError("--init-member picks a network of a policy directory given as --init")
        if init is not None and not (Path(init) / "checkpoint.pt").is_file():
            # a policy directory: adopt its architecture
            policy_file = read_policy(Path(init), init_member)
            config = dataclasses.replace(config, **policy_architecture(*policy_file))
        torch.set_num_threads(config.threads)
        torch.manual_seed(seed)
        self.algo, self.scenario, self.config, self.seed = algo, scenario, config, int(seed)
        self.device = torch.device(device)
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        if backend is None:
            backend = "numpy" if self.device.type == "cpu" else "torch"
        if backend not in ("numpy", "torch") or (backend == "numpy" and self.device.type != "cpu"):
            raise ValueError(f"backend must be 'torch' on {self.device}, or 'numpy' on the CPU")
        self.backend = backend
        self.ladder = [scenario, *(ladder or ())]  # the curriculum's tasks, the current first
        self.curriculum = [task.name for task in self.ladder]
        self.groups: list[dict[str, Any]] = []  # the copies of each N (see _activate)
        self.group_index = 0
        self._start_task(scenario)
        N, D = self.episodes.n_uav, self.step.observation.shape[-1]
        S = int(self.episodes.state().shape[-1])
        self.n_agents, self.obs_dim = N, D
        self.model = ActorCritic(
            algo,
            D,
            N,
            S,
            config.hidden,
            config.activation,
            config.log_std_init,
            config.obs_clip,
            config.value_norm,
        ).to(self.device)
        if policy_file is not None:
            load_actor(self.model, *policy_file)
        elif init is not None or resume:
            saved = self._load_init(Path(out) if resume else Path(init))
        else:  # first statistics from the reset observations
            self.model.obs_norm.update(self._tensor(self.step.observation))
        if algo == "mappo" and (init is None and not resume or policy_file is not None):
            self.model.state_norm.update(self._tensor(self.episodes.state()))
        self.anchor = [p.detach().clone() for p in self.model.actor.parameters()]
        self.optimizer = torch.optim.Adam(
            self.model.parameters(), lr=config.learning_rate, eps=1e-5, fused=True
        )
        self.generator = torch.Generator(self.device).manual_seed(self.seed)
        self.updates = max(1, math.ceil(int(frames) / self.mean_frames_per_update))
        self.frames = 0
        self.update_index = 0
        self.wall = 0.0  # training wall time [s], evaluations excluded
        self.cpu = 0.0  # this process's CPU time of the training [s] (a shared machine's wall
        # time grows with the other processes' load; the CPU time does not)
        # the last 200 finished episodes: mean-over-agents returns and lengths (steps)
        self.finished: deque[float] = deque(maxlen=200)
        self.lengths: deque[int] = deque(maxlen=200)
        self.reward_sum = torch.zeros((), device=self.device)  # the rollout's summed reward
        self.return_scale = (
            RunningNorm(1, math.inf).to(self.device) if config.reward_scaling else None
        )
        self.last_eval: dict[str, Any] = {}
        # the best evaluation on the last task: (completed, -collisions, -J) (see keep_best)
        self.best: list[float] | None = None
        if resume:
            self.optimizer.load_state_dict(saved["optimizer"])
            self.frames, self.update_index = int(saved["frames"]), int(saved["update"])
            self.wall, self.cpu = float(saved["wall_time_s"]), float(saved["cpu_time_s"])
            self.init = str(saved["init"])
            self.best = saved.get("best")

    # ------------------------------------------------------------------ helpers
    def _tensor(self, array: Any, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(array, dtype=dtype, device=self.device)

    def _env_actions(self, actions: torch.Tensor) -> Any:
        return actions if self.backend == "torch" else actions.numpy()

    def _state(self, result: Any = None) -> torch.Tensor | None:
        if self.algo != "mappo":
            return None
        if result is None:
            return self._tensor(self.episodes.state())
        return self._tensor(global_state(self.episodes.sim, result))

    # ------------------------------------------------------------------ rollout
    @torch.no_grad()
    def rollout(self) -> None:
        """Fill the buffers with ``rollout_steps`` steps of every copy and agent."""
        model, cfg = self.model, self.config
        obs, state = self._tensor(self.step.observation), self._state()
        self.reward_sum.zero_()
        for t in range(cfg.rollout_steps):
            self.buf_obs[t] = obs
            if state is not None:
                self.buf_state[t] = state
            actions, log_prob = model.sample(obs, self.generator)
            self.buf_val[t] = model.values_of_copies(obs, state)
            self.buf_act[t], self.buf_logp[t] = actions, log_prob
            step = self.episodes.step(self._env_actions(actions))
            reward = self._tensor(step.reward)
            done = self._tensor(step.done, torch.bool)
            self.episode_return += reward
            self.episode_length += 1
            self.reward_sum += reward.sum()
            learn = self._scaled(reward, done)
            # the copies whose return goes on past their end: truncated, and (unless
            # bootstrap_diverged is off) also those ended by the divergence bounds
            ended = step.truncated if cfg.bootstrap_diverged else step.truncated & ~step.diverged
            if bool(ended.any()):
                final_value = model.values_of_copies(
                    self._tensor(step.final_observation), self._state(step.result)
                )
                truncated = self._tensor(ended, torch.bool)
                learn = bootstrap_truncated(learn, final_value, truncated, cfg.gamma)
            self.buf_rew[t], self.buf_done[t] = learn, done.float()
            if bool(done.any()):
                self.finished.extend(self.episode_return[done].mean(1).tolist())
                self.lengths.extend(self.episode_length[done].tolist())
                self.episode_return[done] = 0.0
                self.episode_length[done] = 0
            self.step = step
            obs, state = self._tensor(step.observation), self._state()
        self.next_value = model.values_of_copies(obs, state)

    def _scaled(self, reward: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        """The reward the learner sees: as given, or divided by the running std of the
        discounted return (``reward_scaling``)."""
        if self.return_scale is None:
            return reward
        self.discounted = self.discounted * self.config.gamma + reward
        self.return_scale.update(self.discounted.reshape(-1, 1))
        self.discounted[done] = 0.0
        return reward / self.return_scale.std().float()

    # ------------------------------------------------------------------ update
    def update(self) -> dict[str, float]:
        """One PPO update on the buffers; returns the last minibatch's losses."""
        cfg, model = self.config, self.model
        if cfg.anneal_lr:
            frac = 1.0 - self.update_index / self.updates
            self.optimizer.param_groups[0]["lr"] = frac * cfg.learning_rate
        T, B, N = self.buf_rew.shape
        advantages, returns = gae(
            self.buf_rew, self.buf_val, self.buf_done[..., None], self.next_value,
            cfg.gamma, cfg.gae_lambda,
        )  # fmt: skip
        if cfg.value_norm:  # the critic's targets in units of the returns seen so far
            model.value_norm.update(returns.reshape(-1, 1))
        rows = (-1, N) if self.algo == "ippo" else (-1,)
        with torch.no_grad():  # the normalisers are frozen during an update: every row once
            actor_in = model.obs_norm(self.buf_obs.reshape(*rows, self.obs_dim))
            if self.buf_state is None:
                critic_in = actor_in
            else:  # row (t, b, n): copy b's state at step t, agent n's observation and one-hot
                state = model.state_norm(self.buf_state.reshape(T * B, -1))
                agent = torch.arange(N, device=self.device).repeat(T * B)
                critic_in = model.state_rows(state.repeat_interleave(N, dim=0), actor_in, agent)
        columns = (
            actor_in,
            critic_in,
            self.buf_act.reshape(*rows, 3),
            self.buf_logp.reshape(rows),
            advantages.reshape(rows),
            model.normalise(returns.reshape(rows)),
            model.normalise(self.buf_val.reshape(rows)),
        )
        count = actor_in.shape[0]
        size = max(1, count // cfg.minibatches)
        stats: dict[str, float] = {}
        for _ in range(cfg.epochs):
            order = torch.randperm(count, generator=self.generator, device=self.device)
            shuffled = [column[order] for column in columns]  # one gather per epoch
            for start in range(0, count, size):
                obs, rows_in, act, old_logp, adv, ret, old_val = (
                    column[start : start + size] for column in shuffled
                )
                log_prob, entropy = model.log_prob_entropy(obs, act)
                value = model.critic(rows_in).squeeze(-1)
                log_ratio = log_prob - old_logp
                ratio = log_ratio.exp()
                if cfg.norm_adv:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = torch.max(
                    -adv * ratio, -adv * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)
                ).mean()
                v_loss = (value - ret) ** 2
                if cfg.clip_vloss:
                    clipped = old_val + (value - old_val).clamp(-cfg.clip_coef, cfg.clip_coef)
                    v_loss = torch.max(v_loss, (clipped - ret) ** 2)
                v_loss = 0.5 * v_loss.mean()
                loss = pg_loss - cfg.ent_coef * entropy.mean() + cfg.vf_coef * v_loss
                if cfg.init_reg > 0:
                    pull = sum(
                        ((p - a) ** 2).sum() for p, a in zip(model.actor.parameters(), self.anchor)
                    )
                    loss = loss + cfg.init_reg * pull
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                # each network clipped on its own: a critic far from the returns early on
                # does not shrink the actor's step
                torch.nn.utils.clip_grad_norm_(model.actor_parameters(), cfg.max_grad_norm)
                torch.nn.utils.clip_grad_norm_(model.critic.parameters(), cfg.max_grad_norm)
                self.optimizer.step()
            with torch.no_grad():  # the epoch's last minibatch
                approx_kl = float(((ratio - 1) - log_ratio).mean())
            stats = {"pg_loss": pg_loss.item(), "v_loss": v_loss.item(), "approx_kl": approx_kl}
            if cfg.target_kl is not None and approx_kl > cfg.target_kl:
                break
        # statistics for the next rollout (frozen during a rollout and its update)
        self.model.obs_norm.update(self.buf_obs)
        if self.buf_state is not None:
            self.model.state_norm.update(self.buf_state)
        self.update_index += 1
        self.frames += self.frames_per_update  # the frames the saved policy has learnt from
        return stats

    # ------------------------------------------------------------------ evaluation and saving
    def evaluate(self) -> dict[str, Any]:
        """Mission metrics of the deterministic actor on the held-out seeds."""
        cfg = self.config
        seeds = list(range(cfg.eval_seed_start, cfg.eval_seed_start + cfg.eval_seeds))
        policy = TorchActorPolicy(self.model, self.device)
        if self.scenario.episode.action == "velocity":
            policy = VelocitySetpointPolicy(
                policy, self.scenario.episode, self.scenario.dynamics.u_max
            )
        batches = run_episode_groups(
            evaluation_scenario(self.scenario), policy, seeds, policy_name=self.algo
        )
        summary = summarise_groups(batches)
        mission = summary["mission"]
        self.last_eval = {
            "task": self.scenario.name,
            "eval_return": float(summary["return_mean"]),
            "eval_completed": int(mission["completed"]),
            "eval_episodes": len(seeds),
            "eval_route_error_max_m": float(mission["route_error_max_m"]),
            "eval_collisions": int(mission["collisions_after_start"]),
            "eval_J": float(summary["realised_cost_mean"]),
        }
        return self.last_eval

    def metadata(self) -> dict[str, Any]:
        """The run's facts written beside the policy and in ``config.yaml``."""
        return {
            "algorithm": self.algo,
            "init": self.init,
            **({} if self.init_member is None else {"init_member": self.init_member}),
            "frames": int(self.frames),
            "wall_time_s": round(self.wall, 2),
            "cpu_time_s": round(self.cpu, 2),
            "scenario": self.scenario.name,
            "curriculum": self.curriculum,
            "training_reward": self.scenario.episode.reward,
            "action_mode": self.scenario.episode.action,
            # what evaluation needs to fly the policy (policies.action_modes, the route slots)
            "velocity_range": self.scenario.episode.velocity_range,
            "velocity_gain": self.scenario.episode.velocity_gain,
            "route_offset": self.scenario.observation.route_offset,
            "seed": self.seed,
        }

    def save(self) -> None:
        """Policy files, checkpoint, config.yaml and the current task's scenario.yaml (what
        evaluation flies the policy on), each replaced atomically."""
        meta = self.metadata()
        self._save_policy(self.out, meta)
        checkpoint = {
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "frames": int(self.frames),
            "update": int(self.update_index),
            "wall_time_s": float(self.wall),
            "cpu_time_s": float(self.cpu),
            "init": self.init,
            "best": self.best,
        }
        atomic_write(self.out / "checkpoint.pt", lambda path: torch.save(checkpoint, path))

    def _save_policy(self, directory: Path, meta: dict[str, Any]) -> None:
        """A policy directory: policy files, config.yaml (``meta`` and the hyper-parameters) and
        the current task's scenario.yaml, each replaced atomically."""
        directory.mkdir(parents=True, exist_ok=True)
        export_policy(directory, self.model, self.scenario, meta)
        atomic_write(directory / "scenario.yaml", lambda path: save_scenario(self.scenario, path))
        config = {**meta, "hyperparams": self.config.as_dict()}
        atomic_write(
            directory / "config.yaml",
            lambda path: path.write_text(yaml.safe_dump(config, sort_keys=False)),
        )

    def keep_best(self) -> bool:
        """Save the policy to ``out/best`` if its last evaluation, on the curriculum's last task,
        beats every earlier one there: more missions completed, then fewer collisions, then a
        lower J. Returns whether it was saved."""
        last = self.last_eval
        if not last or self.scenario.name != self.curriculum[-1]:
            return False
        key = [last["eval_completed"], -last["eval_collisions"], -last["eval_J"]]
        if self.best is not None and key <= self.best:
            return False
        self.best = key
        validation = {name: value for name, value in last.items() if name.startswith("eval_")}
        self._save_policy(self.out / "best", {**self.metadata(), "selected_by": validation})
        return True

    def _load_init(self, directory: Path) -> dict[str, Any]:
        """Load a run directory's ``checkpoint.pt`` into the model (actor, critic and
        normalisers); returns the checkpoint (optimiser state, counters) for a resume."""
        path = directory / "checkpoint.pt"
        if not path.is_file():
            raise ValueError(f"--init / --resume: no checkpoint.pt in {str(directory)!r}")
        state = torch.load(path, map_location=self.device, weights_only=True)
        try:
            self.model.load_state_dict(state["model"])
        except RuntimeError as error:
            first = str(error).splitlines()[1] if "\n" in str(error) else str(error)
            raise ValueError(
                f"--init: {path} does not fit {self.algo} here: {first.strip()}"
            ) from None
        return state

    # ------------------------------------------------------------------ curriculum
    def _start_task(self, scenario: Scenario) -> None:
        """The copies of ``scenario`` (a new task of the curriculum), reset: ``config.copies``
        copies, or as many for each N of a scenario that draws N per reset (one group of copies
        per N, stepped in turn, an update each); the first group active."""
        self.scenario = scenario
        task = self.curriculum.index(scenario.name)
        low, high = n_uav_range(scenario)
        options = SimOptions(
            backend=self.backend, device=self.device if self.backend == "torch" else None
        )
        self.groups = []
        for k, n_uav in enumerate(range(low, high + 1)):
            fixed = {"scene.n_uav": [n_uav, n_uav]}
            drawn = scenario if low == high else with_overrides(scenario, fixed)
            episodes = FormationEpisodes(
                drawn, batch_size=self.config.copies, autoreset=True, options=options
            )
            seed = TRAIN_SEED_BASE * (self.seed + 1) + task * 10_000 + k * 1_000
            self.groups.append(self._group(episodes, episodes.reset(seed=seed)))
        self.group_index = 0
        for name, value in self.groups[0].items():
            setattr(self, name, value)

    def _group(self, episodes: FormationEpisodes, step: Any) -> dict[str, Any]:
        """A group's state: its episodes and current step, running returns and the rollout
        buffers (T, B, N, ...) of its N."""
        T, B, N = self.config.rollout_steps, episodes.batch_size, episodes.n_uav
        D = step.observation.shape[-1]
        zeros = lambda *shape: torch.zeros(shape, device=self.device)  # noqa: E731
        state = int(episodes.state().shape[-1]) if self.algo == "mappo" else 0
        return {
            "episodes": episodes,
            "step": step,
            "episode_return": zeros(B, N),
            "episode_length": torch.zeros(B, dtype=torch.long, device=self.device),
            "discounted": zeros(B, N),
            "buf_obs": zeros(T, B, N, D),
            "buf_act": zeros(T, B, N, 3),
            "buf_logp": zeros(T, B, N),
            "buf_rew": zeros(T, B, N),
            "buf_val": zeros(T, B, N),
            "buf_done": zeros(T, B),
            "buf_state": zeros(T, B, state) if state else None,
            "frames_per_update": T * B * N,
        }

    @property
    def mean_frames_per_update(self) -> float:
        """Agent-steps of an update, on average over the groups (stepped round robin)."""
        return float(np.mean([group["frames_per_update"] for group in self.groups]))

    def _activate(self, index: int) -> None:
        """Make group ``index`` the one the rollout and update work on: the trainer's
        ``episodes``, ``step``, running returns and ``buf_*`` are the active group's."""
        if index == self.group_index:
            return
        current = self.groups[self.group_index]
        for name in current:
            current[name] = getattr(self, name)
        for name, value in self.groups[index].items():
            setattr(self, name, value)
        self.group_index = index

    def promote(self) -> bool:
        """Move to the next task of the curriculum if the last evaluation completed at least
        ``promote_at`` of its missions and its mean route error max is at most
        ``promote_route_error`` [m] (0: no bound); returns whether it moved."""
        following = self.curriculum.index(self.scenario.name) + 1
        if following >= len(self.ladder) or not self.last_eval:
            return False
        rate = self.last_eval["eval_completed"] / max(1, self.last_eval["eval_episodes"])
        if rate < self.config.promote_at:
            return False
        bound = self.config.promote_route_error
        if bound and not self.last_eval["eval_route_error_max_m"] <= bound:
            return False
        self._start_task(self.ladder[following])
        return True

    # ------------------------------------------------------------------ loop
    def train(self, progress: bool = True) -> dict[str, Any]:
        """Run every update (evaluating every ``eval_every``); saves at evaluations, at the end
        and on Ctrl-C. Returns the run's metadata with the last evaluation."""
        from tqdm.auto import tqdm

        save_scenario(self.scenario, self.out / "scenario.yaml")
        total = round(self.updates * self.mean_frames_per_update)
        bar = tqdm(total=total, initial=self.frames, unit="frame", disable=not progress)
        resumed = self.update_index > 0
        csv_file = open(  # noqa: SIM115
            self.out / "progress.csv", "a" if resumed else "w", newline="", encoding="utf-8"
        )
        writer = csv.DictWriter(csv_file, fieldnames=PROGRESS_COLUMNS)
        if not resumed:
            writer.writeheader()
        start = time.perf_counter() - self.wall
        cpu_start = time.process_time() - self.cpu
        try:
            while self.update_index < self.updates:
                self._activate(self.update_index % len(self.groups))
                self.rollout()
                self.update()
                self.wall = time.perf_counter() - start
                self.cpu = time.process_time() - cpu_start
                row: dict[str, Any] = {
                    "update": self.update_index,
                    "frames": self.frames,
                    "wall_s": round(self.wall, 2),
                    "cpu_s": round(self.cpu, 2),
                    "fps": round(self.frames / self.wall, 1),
                    "mean_reward": round(float(self.reward_sum) / self.frames_per_update, 5),
                    "mean_return": round(float(np.mean(self.finished)), 4) if self.finished else "",
                    "mean_length": round(float(np.mean(self.lengths)), 1) if self.lengths else "",
                    "episodes": len(self.finished),
                }
                every = self.config.eval_every
                if (every and self.update_index % every == 0) or self.update_index == self.updates:
                    row.update(self.evaluate())
                    self.keep_best()
                    self.save()
                    self.promote()
                    start = time.perf_counter() - self.wall  # evaluation time is not training
                    cpu_start = time.process_time() - self.cpu
                writer.writerow(row)
                csv_file.flush()
                bar.update(self.frames_per_update)
                last = self.last_eval
                bar.set_postfix(
                    fps=row["fps"],
                    ret=row["mean_return"],
                    done=f"{last['eval_completed']}/{last['eval_episodes']}" if last else "-",
                )
        except KeyboardInterrupt:
            self.save()
            print(f"interrupted: saved {self.out} at {self.frames} frames", file=sys.stderr)
        finally:
            bar.close()
            csv_file.close()
        return {**self.metadata(), **self.last_eval}
