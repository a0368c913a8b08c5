"""Networks of the on-policy trainer: observation normaliser, MLPs shared or per agent, and the
actor-critic of PPO (parameter sharing), MAPPO (centralised critic) and IPPO (one network per UAV).

Shapes: a shared network maps (..., dim) to (..., out); a per-agent one (IPPO) maps (..., N, dim)
to (..., N, out) with weights (N, out, in), one batched matmul for all agents.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn
from torch.nn.functional import linear, one_hot

ACTIONS = 3  # normalised acceleration command per UAV
_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)
_ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "gelu": nn.GELU, "silu": nn.SiLU}


class RunningNorm(nn.Module):
    """Running mean and variance of (..., dim) inputs (parallel Welford, float64 buffers);
    ``forward`` returns ``clip((x - mean) / sqrt(var + eps), -clip, +clip)`` in float32."""

    def __init__(self, dim: int, clip: float, eps: float = 1e-8) -> None:
        super().__init__()
        self.dim, self.clip, self.eps = int(dim), float(clip), float(eps)
        self.register_buffer("mean", torch.zeros(dim, dtype=torch.float64))
        self.register_buffer("var", torch.ones(dim, dtype=torch.float64))
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Merge the statistics of a batch (..., dim) into the running ones."""
        x = x.reshape(-1, self.dim).to(torch.float64)
        n = x.shape[0]
        batch_mean, batch_var = x.mean(0), x.var(0, unbiased=False)
        delta, total = batch_mean - self.mean, self.count + n
        self.mean += delta * n / total
        m2 = self.var * self.count + batch_var * n + delta**2 * self.count * n / total
        self.var.copy_(m2 / total)
        self.count.copy_(total)

    def std(self) -> torch.Tensor:
        """(dim,) float64 divisor of the normalisation."""
        return torch.sqrt(self.var + self.eps)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        mean, std = self.mean.to(x.dtype), self.std().to(x.dtype)
        return ((x - mean) / std).clamp(-self.clip, self.clip).float()


class Linear(nn.Module):
    """A linear layer, shared (``agents=None``: weight (out, in)) or per agent (weight
    (agents, out, in), input (..., agents, in)); orthogonal init with ``gain``, zero bias."""

    def __init__(self, n_in: int, n_out: int, agents: int | None, gain: float) -> None:
        super().__init__()
        self.agents = agents
        lead = () if agents is None else (agents,)
        self.weight = nn.Parameter(torch.empty(*lead, n_out, n_in))
        self.bias = nn.Parameter(torch.zeros(*lead, n_out))
        for w in self.weight.view(-1, n_out, n_in):
            nn.init.orthogonal_(w, gain)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.agents is None:
            return linear(x, self.weight, self.bias)
        return torch.einsum("...ni,noi->...no", x, self.weight) + self.bias


class MLP(nn.Module):
    """Hidden layers ``act(W h + b)`` then a linear output layer (init gain ``out_gain``)."""

    def __init__(
        self,
        n_in: int,
        hidden: tuple[int, ...],
        n_out: int,
        activation: str,
        agents: int | None,
        out_gain: float,
    ) -> None:
        super().__init__()
        sizes = (n_in, *hidden)
        layers: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            layers += [Linear(a, b, agents, math.sqrt(2.0)), _ACTIVATIONS[activation]()]
        layers.append(Linear(sizes[-1], n_out, agents, out_gain))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)

    def linears(self) -> list[Linear]:
        """The linear layers in order (the exported ``w{l}``, ``b{l}``)."""
        return [m for m in self.net if isinstance(m, Linear)]


class ActorCritic(nn.Module):
    """Gaussian actor with state-independent log std, and a critic, for one algorithm.

    - ``ppo``: shared actor and critic on the agent's own observation;
    - ``mappo``: shared actor; critic on the normalised global state (S,) and a one-hot agent id;
    - ``ippo``: actor and critic per agent (inputs keep their agent axis: (..., N, dim)).

    Args:
        algo: ``"ppo"``, ``"mappo"`` or ``"ippo"``.
        obs_dim: one agent's observation width.
        n_agents: N (the one-hot width of MAPPO, the agent axis of IPPO).
        state_dim: the global state's width (MAPPO; else ignored).
        hidden, activation, log_std_init, obs_clip, value_norm: see
            :class:`~uav_formation_baselines.onpolicy_config.OnPolicyConfig`; with
            ``value_norm`` the critic predicts values in units of the running return statistics
            (:meth:`value` converts them back).
    """

    def __init__(
        self,
        algo: str,
        obs_dim: int,
        n_agents: int,
        state_dim: int,
        hidden: tuple[int, ...],
        activation: str,
        log_std_init: float,
        obs_clip: float,
        value_norm: bool = False,
    ) -> None:
        super().__init__()
        self.algo, self.n_agents, self.activation = algo, int(n_agents), activation
        self.normalise_values = bool(value_norm)
        self.value_norm = RunningNorm(1, math.inf)  # returns' statistics (value_norm=True)
        agents = self.n_agents if algo == "ippo" else None
        self.obs_norm = RunningNorm(obs_dim, obs_clip)
        self.actor = MLP(obs_dim, hidden, ACTIONS, activation, agents, 0.01)
        lead = () if agents is None else (agents,)
        self.log_std = nn.Parameter(torch.full((*lead, ACTIONS), float(log_std_init)))
        critic_in = obs_dim
        if algo == "mappo":
            self.state_norm = RunningNorm(state_dim, obs_clip)
            critic_in = state_dim + obs_dim + self.n_agents
        self.critic = MLP(critic_in, hidden, 1, activation, agents, 1.0)

    def mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """(..., 3) mean of the normalised action (before the env's clip to [-1, 1])."""
        return self.actor(self.obs_norm(obs))

    def log_prob_entropy(
        self, normed: torch.Tensor, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Log density of ``actions`` (..., 3) under the policy at normalised observations
        ``normed`` (..., dim), and the entropy, each (...,) summed over the action axes."""
        mean = self.actor(normed)
        log_std = self.log_std.expand_as(mean)
        z = (actions - mean) * torch.exp(-log_std)
        log_prob = (-0.5 * z**2 - log_std - _HALF_LOG_2PI).sum(-1)
        return log_prob, (log_std + 0.5 + _HALF_LOG_2PI).sum(-1)

    @torch.no_grad()
    def sample(
        self, obs: torch.Tensor, generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Sampled actions (..., 3) and their log density (...,)."""
        mean = self.mean_action(obs)
        std = self.log_std.exp().expand_as(mean)
        noise = torch.randn(mean.shape, generator=generator, device=mean.device)
        actions = mean + std * noise
        log_prob = (-0.5 * noise**2 - self.log_std - _HALF_LOG_2PI).sum(-1)
        return actions, log_prob

    def critic_input(
        self, obs: torch.Tensor, state: torch.Tensor | None, agent: torch.Tensor | None
    ) -> torch.Tensor:
        """The critic's input rows: the normalised observation, or for MAPPO the agent-specific
        global state: the normalised state (..., S), the agent's own normalised observation
        and the one-hot of ``agent`` (...,) integer ids."""
        if self.algo != "mappo":
            return self.obs_norm(obs)
        return self.state_rows(self.state_norm(state), self.obs_norm(obs), agent)

    def state_rows(
        self, normed_state: torch.Tensor, normed_obs: torch.Tensor, agent: torch.Tensor
    ) -> torch.Tensor:
        """MAPPO's critic rows: a normalised state (..., S), the agent's normalised observation
        (..., dim) and the one-hot of ``agent``."""
        onehot = one_hot(agent, self.n_agents).to(normed_state.dtype)
        return torch.cat([normed_state, normed_obs, onehot], dim=-1)

    def value(
        self,
        obs: torch.Tensor,
        state: torch.Tensor | None = None,
        agent: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(...,) value of each row (see :meth:`critic_input`)."""
        return self.denormalise(self.critic(self.critic_input(obs, state, agent)).squeeze(-1))

    def normalise(self, values: torch.Tensor) -> torch.Tensor:
        """Values in the critic's output units (identity without ``value_norm``)."""
        if not self.normalise_values:
            return values
        norm = self.value_norm
        return (values - norm.mean.float()) / norm.std().float()

    def denormalise(self, output: torch.Tensor) -> torch.Tensor:
        """The critic's output in return units (identity without ``value_norm``)."""
        if not self.normalise_values:
            return output
        norm = self.value_norm
        return output * norm.std().float() + norm.mean.float()

    def actor_parameters(self) -> list[nn.Parameter]:
        """The actor's parameters (its MLP and the log std)."""
        return [*self.actor.parameters(), self.log_std]

    def values_of_copies(self, obs: torch.Tensor, state: torch.Tensor | None) -> torch.Tensor:
        """(B, N) values of copies' observations (B, N, dim) and states (B, S)."""
        if self.algo != "mappo":
            return self.value(obs)
        batch = obs.shape[0]
        agent = torch.arange(self.n_agents, device=obs.device).expand(batch, -1)
        return self.value(obs, state[:, None, :].expand(-1, self.n_agents, -1), agent)

    def exported_arrays(self) -> dict[str, np.ndarray]:
        """The actor as arrays of the policy-file format (``obs_mean``, ``obs_std``, ``m0.w{l}``,
        ``m0.b{l}``; per-agent weights keep their leading N axis)."""
        arrays = {
            "obs_mean": self.obs_norm.mean.cpu().numpy().astype(np.float32),
            "obs_std": self.obs_norm.std().cpu().numpy().astype(np.float32),
        }
        for index, layer in enumerate(self.actor.linears()):
            arrays[f"m0.w{index}"] = layer.weight.detach().cpu().numpy().astype(np.float32)
            arrays[f"m0.b{index}"] = layer.bias.detach().cpu().numpy().astype(np.float32)
        return arrays


class TorchActorPolicy:
    """The deterministic actor as a policy of the evaluation runner: ``act_batch(obs (B, N, dim))
    -> (B, N, 3)`` numpy clipped mean actions."""

    def __init__(self, model: ActorCritic, device: torch.device | str = "cpu") -> None:
        self.model, self.device = model, torch.device(device)

    @torch.no_grad()
    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        x = torch.as_tensor(np.asarray(obs), dtype=torch.float32, device=self.device)
        return self.model.mean_action(x).clamp(-1.0, 1.0).cpu().numpy().astype(np.float64)
