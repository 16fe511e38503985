"""The trainer's parts, each built from the Hydra config (``conf/config.yaml``): env, agent, replay, collector, optimiser.

Each ``make_*`` is usable on its own, e.g. to put our replay or collector into another TorchRL loop.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict.nn import TensorDictSequential
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.envs import EnvBase
from torchrl.objectives import SoftUpdate, group_optimizers

from torchrl_cebp.agents import HERDDPGLoss, ObsGoalNormalizer, make_critic
from torchrl_cebp.envs import FRANKA_TASK, make_env_from_config
from torchrl_cebp.envs.franka import FrankaLayout
from torchrl_cebp.envs.goal_spaces import get_goal_space
from torchrl_cebp.replay import HindsightRelabel, episode_rows, make_replay_buffer
from torchrl_cebp.replay.samplers import PerWorkerSampler, WorkerLayout
from torchrl_cebp.training.collection import EpisodeBatches, make_collector, make_policy


def derive_seed(*keys: int) -> int:
    """A 31-bit seed for one stream (e.g. ``(seed, epoch, stream)``), independent of the others.

    Args:
        *keys (int): non-negative integers naming the stream.

    Example:
        >>> derive_seed(0, 1) == derive_seed(0, 1) != derive_seed(0, 2)
        True
    """
    return int(np.random.SeedSequence(list(keys)).generate_state(1)[0] >> 1)


def make_env(cfg: DictConfig, n_envs: int = 1, device: torch.device | str = "cpu", training: bool = False) -> EnvBase:
    """``n_envs`` simulations of the configured task (``cfg.env``: task, goal space, robot) as one batched env.

    ``training=True`` gives the exploration episodes' envs, which begin ``env.grasped_start`` of them with the cube
    grasped; test envs always start from the table.

    Args:
        cfg (DictConfig): the training config.
        n_envs (int, optional): the simulations. Defaults to ``1``.
        device (torch.device or str, optional): where the env's tensors live. Defaults to ``"cpu"``.
        training (bool, optional): build the exploration episodes' envs. Defaults to ``False``.

    Example:
        >>> from omegaconf import OmegaConf
        >>> make_env(OmegaConf.create({"env": {"task": "push", "goal_space": "standard"}}), 2).batch_size
        torch.Size([2])
    """
    grasped_start = (cfg.env.get("grasped_start") or 0.0) if training else 0.0
    return make_env_from_config(cfg.env, device=device, num_envs=n_envs, grasped_start=grasped_start)


@dataclass(frozen=True)
class TaskDims:
    """The sizes the networks are built for, and the episode length, read from an env's specs.

    Args:
        observation (int): the observation size.
        goal (int): the goal size.
        action (int): the action size.
        episode_steps (int): steps per episode.

    Example:
        >>> from torchrl_cebp.envs import make_env
        >>> TaskDims.of(make_env("push", "extended", control="joint"))
        TaskDims(observation=25, goal=3, action=7, episode_steps=50)
    """

    observation: int
    goal: int
    action: int
    episode_steps: int

    @classmethod
    def of(cls, env: EnvBase) -> TaskDims:
        """The dims of ``env``.

        Args:
            env (EnvBase): a :class:`~torchrl_cebp.envs.TouchFetchEnv`.
        """
        spec = env.observation_spec
        return cls(spec["observation"].shape[-1], spec["desired_goal"].shape[-1], env.action_spec.shape[-1],
                   env.max_episode_steps)


@dataclass
class Agent:
    """DDPG+HER's modules, as :func:`make_agent` builds them.

    Args:
        policy (TensorDictSequential): the deterministic policy (normaliser, actor).
        exploration (TensorDictSequential): the exploration policy wrapping it.
        loss (HERDDPGLoss): actor, critic and their target copies.
        target_updater (SoftUpdate): the soft update of the target copies.

    Example:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"agent": {"hidden": [32], "random_eps": 0.3, "noise_std": 0.2,
        ...                                   "action_l2": 1.0, "tau": 0.05}})
        >>> agent = make_agent(cfg, TaskDims(25, 3, 4, 50))
        >>> agent.exploration[0] is agent.policy, type(agent.normalizer).__name__
        (True, 'ObsGoalNormalizer')
    """

    policy: TensorDictSequential
    exploration: TensorDictSequential
    loss: HERDDPGLoss
    target_updater: SoftUpdate

    @property
    def normalizer(self) -> ObsGoalNormalizer:
        """The policy's observation and goal normaliser."""
        return self.policy[0]


def make_agent(cfg: DictConfig, dims: TaskDims, device: torch.device | str = "cpu") -> Agent:
    """Actor, critic, DDPG loss with HER's discount ``1 - 1/T`` and its soft target update (``cfg.agent``).

    Args:
        cfg (DictConfig): the training config; reads ``cfg.agent``.
        dims (TaskDims): the task's sizes and episode length ``T``.
        device (torch.device or str, optional): where the modules live. Defaults to ``"cpu"``.

    Example:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"agent": {"hidden": [32], "random_eps": 0.3, "noise_std": 0.2,
        ...                                   "action_l2": 1.0, "tau": 0.05}})
        >>> agent = make_agent(cfg, TaskDims(25, 3, 4, 50))
        >>> agent.policy[1] is agent.loss.actor_network  # the loss trains the policy's own actor
        True
    """
    agent_cfg = cfg.agent
    policy, exploration = make_policy(
        dims.observation, dims.goal, dims.action, list(agent_cfg.hidden),
        random_eps=agent_cfg.random_eps, noise_std=agent_cfg.noise_std,
    )
    policy.to(device)
    exploration.to(device)
    critic = make_critic(dims.observation + dims.goal, dims.action, list(agent_cfg.hidden)).to(device)
    loss = HERDDPGLoss(policy[1], critic, gamma=1.0 - 1.0 / dims.episode_steps, action_l2=agent_cfg.action_l2)
    return Agent(policy, exploration, loss, SoftUpdate(loss, tau=agent_cfg.tau))


def make_optimizer(cfg: DictConfig, loss: HERDDPGLoss) -> torch.optim.Optimizer:
    """One Adam over the actor's and the critic's parameters, each with its learning rate (``cfg.agent``).

    Args:
        cfg (DictConfig): the training config; reads ``cfg.agent.lr_actor`` and ``cfg.agent.lr_critic``.
        loss (HERDDPGLoss): the loss whose parameters it trains.
    """
    # Fused: one kernel per step instead of a dozen per parameter group (~1 ms of 15 per update).
    actor = torch.optim.Adam(loss.actor_network_params.values(True, True), lr=cfg.agent.lr_actor, fused=True)
    critic = torch.optim.Adam(loss.value_network_params.values(True, True), lr=cfg.agent.lr_critic, fused=True)
    return group_optimizers(actor, critic)


def replay_layout(cfg: DictConfig) -> str:
    """How the emulated workers replay: ``"per_worker"`` (a buffer, sampler and draw each, as baselines' MPI
    workers), ``"merged"`` (one buffer drawing ``workers x batch_size``) or ``"single"`` (one worker).

    Args:
        cfg (DictConfig): the training config; reads ``workers`` and ``replay.per_worker``.

    Example:
        >>> from omegaconf import OmegaConf
        >>> replay_layout(OmegaConf.create({"workers": 8, "replay": {"per_worker": True}}))
        'per_worker'
    """
    if cfg.workers == 1:
        return "single"
    return "per_worker" if cfg.replay.per_worker else "merged"


def replay_capacity(cfg: DictConfig) -> int:
    """The transitions the replay's storage holds: ``replay.capacity`` rounded up to whole episodes of the task, as
    TorchRL's episode storage rounds it (:func:`~torchrl_cebp.replay.episode_rows`; 70-step Slide: 1,000,020).

    With ``replay.capacity_per: worker`` and several workers, each worker holds ``replay.capacity`` of its own, as
    each of baselines' MPI workers holds its own 1e6: the storage holds ``workers`` times that, each worker's share
    rounded up to whole cycles of its ``rollouts_per_cycle`` episodes so that the workers' shares are equal.

    Args:
        cfg (DictConfig): the training config.

    Example:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"workers": 8, "rollouts_per_cycle": 2, "env": {"episode_steps": 70},
        ...                         "replay": {"capacity": 1_000_000, "capacity_per": "total"}})
        >>> replay_capacity(cfg), replay_capacity(OmegaConf.merge(cfg, {"replay": {"capacity_per": "worker"}}))
        (1000020, 8000160)
    """
    steps = episode_steps(cfg)
    rows = episode_rows(cfg.replay.capacity, steps)
    if cfg.replay.get("capacity_per", "total") == "worker" and cfg.workers > 1:
        cycles = -(rows // -cfg.rollouts_per_cycle)
        rows = cycles * cfg.rollouts_per_cycle * cfg.workers
    return rows * steps


def worker_share(capacity: int, episode_steps: int, workers: int, episodes_per_worker: int) -> int:
    """The most transitions one worker's rows hold of a storage of ``capacity`` (see :class:`~torchrl_cebp.replay.samplers.WorkerRows`).

    Args:
        capacity (int): the storage's transitions.
        episode_steps (int): steps per episode.
        workers (int): the emulated workers.
        episodes_per_worker (int): each worker's episodes per cycle.

    Example:
        >>> worker_share(1_000_000, 50, 8, 2), worker_share(1_000_000, 70, 8, 2)
        (125000, 125020)
    """
    layout = WorkerLayout(workers, episodes_per_worker)
    return layout.rows_of_worker(episode_rows(capacity, episode_steps), 0) * episode_steps


def make_sampler(cfg: DictConfig) -> Sampler:
    """The replay sampler of ``cfg.sampler``; with per-worker replay, one per worker inside a :class:`PerWorkerSampler`.

    Worker ``w`` gets the episodes of its ``rollouts_per_cycle`` envs. A PER (one, or a worker's shard) holds
    priorities for every transition its rows of the storage hold (:func:`replay_capacity`); the ``capacity`` of its
    config only says that it takes one. A shard with a ``seed`` (MEP's density model) gets one of its own.

    Args:
        cfg (DictConfig): the training config; ``cfg.sampler`` is instantiated with Hydra.

    Example:
        >>> from omegaconf import OmegaConf
        >>> cfg = OmegaConf.create({"seed": 0, "workers": 4, "rollouts_per_cycle": 2, "replay": {"per_worker": True},
        ...                         "sampler": {"_target_": "torchrl_cebp.replay.samplers.UniformEpisodeSampler"}})
        >>> make_sampler(cfg)
        PerWorkerSampler(workers=4, episodes_per_worker=2, sampler=UniformEpisodeSampler(n_episodes=0))
    """
    per_worker = replay_layout(cfg) == "per_worker"
    workers = cfg.workers if per_worker else 1
    shards = []
    for worker in range(workers):
        own = {}
        if "capacity" in cfg.sampler:
            own["capacity"] = worker_share(replay_capacity(cfg), episode_steps(cfg), workers, cfg.rollouts_per_cycle)
        if "seed" in cfg.sampler and per_worker:
            own["seed"] = derive_seed(cfg.sampler.seed, worker)
        shards.append(instantiate(cfg.sampler, **own))
    return PerWorkerSampler(*shards, episodes_per_worker=cfg.rollouts_per_cycle) if per_worker else shards[0]


def make_replay(cfg: DictConfig, sampler: Sampler, env: EnvBase) -> tuple[TensorDictReplayBuffer, HindsightRelabel]:
    """The episode replay of ``cfg.replay`` with ``sampler`` and HER relabelling against ``env``'s reward.

    Its draws come from a generator of their own, seeded from ``cfg.seed``: TorchRL's PER would
    otherwise draw from numpy's unseeded global RNG.

    Args:
        cfg (DictConfig): the training config.
        sampler (Sampler): the replay's sampler (:func:`make_sampler`).
        env (EnvBase): the env whose ``compute_reward`` relabels.

    Returns:
        the replay buffer and its HER relabelling transform.
    """
    her = HindsightRelabel(env.compute_reward, future_p=cfg.replay.future_p, strategy=cfg.replay.strategy)
    replay = make_replay_buffer(sampler, her, capacity=replay_capacity(cfg), batch_size=cfg.batch_size * cfg.workers,
                                generator=torch.Generator().manual_seed(derive_seed(cfg.seed, 3)))
    return replay, her


def episode_steps(cfg: DictConfig) -> int | None:
    """Steps per episode of the configured task, without building it (``None`` if the env config is invalid).

    Args:
        cfg (DictConfig): the training config.

    Example:
        >>> from omegaconf import OmegaConf
        >>> episode_steps(OmegaConf.create({"env": {"task": "slide", "goal_space": "extended"}}))
        70
    """
    task, goal_space = OmegaConf.select(cfg, "env.task"), OmegaConf.select(cfg, "env.goal_space")
    if OmegaConf.select(cfg, "env.episode_steps") is not None:
        return cfg.env.episode_steps
    if task == FRANKA_TASK:
        return FrankaLayout().max_episode_steps
    try:
        return get_goal_space(task, goal_space).max_episode_steps
    except ValueError:
        return None


def episodes_per_cycle(cfg: DictConfig) -> int:
    """Episodes a cycle collects: baselines' ``rollouts_per_cycle`` per emulated worker.

    Args:
        cfg (DictConfig): the training config.
    """
    return cfg.rollouts_per_cycle * cfg.workers


def collector_processes(cfg: DictConfig) -> int:
    """Env processes of the training collector: ``cfg.collector_processes``, at least one to overlap collection.

    Args:
        cfg (DictConfig): the training config.
    """
    return max(cfg.collector_processes, 1) if cfg.overlap_collection else cfg.collector_processes


def make_training_collector(cfg: DictConfig, agent: Agent, dims: TaskDims) -> EpisodeBatches:
    """Exploration episodes of ``agent`` on CPU envs, a cycle's worth per batch.

    Args:
        cfg (DictConfig): the training config.
        agent (Agent): whose exploration policy collects.
        dims (TaskDims): the task's sizes and episode length.

    Returns:
        :class:`~torchrl_cebp.training.collection.EpisodeBatches` over a collector of
        :func:`~torchrl_cebp.training.collection.make_collector`.
    """
    collector = make_collector(
        functools.partial(make_env, cfg, training=True), copy.deepcopy(agent.exploration), n_envs=episodes_per_cycle(cfg),
        episode_steps=dims.episode_steps, processes=collector_processes(cfg),
    )
    return EpisodeBatches(collector, agent.exploration)
