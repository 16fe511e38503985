"""DDPG + HER training with any of the replay samplers, as in baselines' HER, over TorchRL's loss, target updater and collectors.

An epoch is ``cycles_per_epoch`` cycles; a cycle collects ``rollouts_per_cycle x workers``
whole episodes, stores them, runs ``updates_per_cycle`` updates of ``batch_size x workers``
transitions, and moves the target networks. Each epoch ends with deterministic test episodes,
a CSV row and a checkpoint. With ``overlap_collection`` an env process collects the next cycle's
episodes while this one's updates run.
"""

from __future__ import annotations

import os
import time
from collections import defaultdict
from pathlib import Path

import torch
from omegaconf import DictConfig
from tensordict import TensorDict, TensorDictBase
from torchrl.data import TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.data.replay_buffers.scheduler import LinearScheduler
from tqdm import tqdm

from torchrl_cebp.replay import HindsightRelabel
from torchrl_cebp.replay.samplers import EpisodeSampler
from torchrl_cebp.training.builders import (
    Agent,
    TaskDims,
    derive_seed,
    episodes_per_cycle,
    make_agent,
    make_env,
    make_optimizer,
    make_replay,
    make_sampler,
    make_training_collector,
    replay_capacity,
    replay_layout,
)
from torchrl_cebp.training.checkpoint import (
    BestPolicy,
    RunCheckpoints,
    has_checkpoint,
    policy_state,
    restore_training_state,
    save_policy,
    training_state,
)
from torchrl_cebp.training.collection import EpisodeBatches
from torchrl_cebp.training.config import ConfigError, resolve_device, validate_config, warn_if_bf16_is_emulated
from torchrl_cebp.training.evaluation import evaluate_success_rate
from torchrl_cebp.training.metrics import EpochLog, ExplorationLog
from torchrl_cebp.training.run_lock import RunFolderLock

# The streams derive_seed(seed, epoch, stream) names: each epoch restarts them, so a resumed run repeats.
COLLECTION_STREAM, TEST_STREAM = 0, 1


class RelabelledTransitions:
    """Every transition of a batch of new episodes ``[n, T]``, its goal relabelled as the replay would.

    Baselines feeds its normaliser such relabelled transitions of each new batch of
    episodes, so the goal statistics cover the goals the networks are trained on
    (independently of how the sampler draws from the buffer). It relabels through the
    replay's own :meth:`HindsightRelabel.relabel`.

    Args:
        her (HindsightRelabel): the replay's relabelling.

    Example:
        >>> from torchrl_cebp.envs import make_env
        >>> env = make_env("push", num_envs=2)
        >>> feed = RelabelledTransitions(HindsightRelabel(env.compute_reward))
        >>> feed(env.rollout(50))["desired_goal"].shape
        torch.Size([100, 3])
    """

    def __init__(self, her: HindsightRelabel) -> None:
        self.her = her

    def __call__(self, episodes: TensorDictBase) -> TensorDictBase:
        n_episodes, episode_steps = episodes.shape[:2]
        rows, steps = torch.meshgrid(torch.arange(n_episodes), torch.arange(episode_steps), indexing="ij")
        goal = self.her.relabel(episodes, rows.reshape(-1), steps.reshape(-1))[self.her.goal_key]
        return TensorDict({"observation": episodes["observation"].reshape(goal.shape[0], -1), "desired_goal": goal},
                          [goal.shape[0]])


def sampling_spread(sampler: Sampler) -> dict[str, float]:
    """Effective fraction of stored episodes an episode sampler draws from, ``1 / (N sum p^2)``.

    Args:
        sampler (Sampler): the replay's sampler.

    Returns:
        ``{"priority_ess_fraction": ...}`` for an episode-priority sampler holding episodes, else ``{}``.
    """
    if not isinstance(sampler, EpisodeSampler) or not sampler.n_episodes:
        return {}
    n = sampler.n_episodes
    p = sampler.probabilities(torch.arange(n))
    return {"priority_ess_fraction": (1.0 / (n * p.square().sum())).item()}


def beta_annealing(sampler: Sampler) -> LinearScheduler | None:
    """PER's linear beta schedule over its draws (every worker's at once), or ``None`` for other samplers.

    Args:
        sampler (Sampler): the replay's sampler, possibly a per-worker one.
    """
    # A per-worker sampler's schedule sets every worker's beta; the checkpoint keeps its step count.
    scheduler = getattr(sampler, "beta_scheduler", None)
    return None if scheduler is None else scheduler()


class Learner:
    """The gradient side of a cycle: store episodes, draw, update actor and critic, move the targets.

    Args:
        cfg (DictConfig): the training config.
        agent (Agent): the modules it trains.
        optimizer (torch.optim.Optimizer): over the actor's and critic's parameters.
        replay (TensorDictReplayBuffer): the episode replay.
        her (HindsightRelabel): the replay's relabelling, which also feeds the normaliser.
        sampler (Sampler): the replay's sampler.
        device (torch.device): where the updates run.
        exploration (ExplorationLog, optional): measures how far the stored episodes explored, for
            :meth:`epoch_means`. Defaults to ``None`` (not measured).

    Example:
        >>> from torchrl_cebp.training.builders import make_optimizer
        >>> from torchrl_cebp.training.config import compose_config
        >>> cfg = compose_config("batch_size=8", "replay.capacity=5000", "agent.hidden=[32]")
        >>> env = make_env(cfg, 2)
        >>> agent = make_agent(cfg, TaskDims.of(env))
        >>> sampler = make_sampler(cfg)
        >>> replay, her = make_replay(cfg, sampler, env)
        >>> learner = Learner(cfg, agent, make_optimizer(cfg, agent.loss), replay, her, sampler, torch.device("cpu"))
        >>> with torch.no_grad():
        ...     episodes = env.rollout(50, agent.exploration)
        >>> learner.store(episodes)
        >>> learner.update()
        >>> sorted(learner.totals)
        ['action_l2', 'loss_actor', 'loss_value', 'q_mean']
    """

    def __init__(self, cfg: DictConfig, agent: Agent, optimizer: torch.optim.Optimizer, replay: TensorDictReplayBuffer,
                 her: HindsightRelabel, sampler: Sampler, device: torch.device,
                 exploration: ExplorationLog | None = None) -> None:
        self.cfg, self.agent, self.optimizer, self.replay, self.sampler, self.device = (
            cfg, agent, optimizer, replay, sampler, device)
        self.exploration = exploration
        self.normalizer_feed = RelabelledTransitions(her)
        self.beta_scheduler = beta_annealing(sampler)
        self.totals: dict[str, torch.Tensor] = defaultdict(float)

    def store(self, episodes: TensorDictBase) -> None:
        """Adds whole episodes to the replay and their relabelled transitions to the normaliser.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes.
        """
        self.replay.extend(episodes)
        self.agent.normalizer.update(self.normalizer_feed(episodes))
        if self.exploration is not None:
            self.exploration.update(episodes)

    def update(self) -> None:
        """One draw and one gradient step of actor and critic; the drawn priorities are updated."""
        batch = self.replay.sample().to(self.device)
        if self.beta_scheduler is not None:
            self.beta_scheduler.step()
        self.agent.normalizer(batch)
        self.agent.normalizer(batch["next"])
        with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.cfg.precision == "bf16"):
            losses = self.agent.loss(batch)
        self.optimizer.zero_grad()
        (losses["loss_actor"] + losses["loss_value"]).backward()
        self.optimizer.step()
        self.replay.update_tensordict_priority(batch)
        for key in ("loss_actor", "loss_value", "action_l2"):
            self.totals[key] += losses[key].detach()
        self.totals["q_mean"] += losses["pred_value"].mean()
        if "priority_weight" in batch.keys():
            self.totals["is_weight_mean"] += batch["priority_weight"].mean()
            self.totals["is_weight_min"] += batch["priority_weight"].min()

    def refit_sampler(self) -> None:
        """The sampler's once-an-epoch refit on the stored episodes (MEP's density model)."""
        refit = getattr(self.sampler, "refit", None)
        if refit is not None:
            refit(self.replay.storage)

    def epoch_means(self) -> dict[str, float]:
        """Per-update means of the losses and weights since the last call, the sampler's spread, and how far the
        episodes stored since the last call explored."""
        n_updates = self.cfg.cycles_per_epoch * self.cfg.updates_per_cycle
        means = {key: (value / n_updates).item() for key, value in self.totals.items()}
        self.totals.clear()
        explored = self.exploration.compute() if self.exploration is not None else {}
        return {**means, **sampling_spread(self.sampler), **explored}


def run_epoch(cfg: DictConfig, epoch: int, learner: Learner, batches: EpisodeBatches) -> dict[str, float]:
    """One epoch's cycles.

    Args:
        cfg (DictConfig): the training config.
        epoch (int): the epoch, which seeds its collection streams.
        learner (Learner): stores the episodes and runs the updates.
        batches (EpisodeBatches): collects the episodes.

    Returns:
        ``collect_s`` and ``update_s`` (seconds) and ``load_avg``, the mean load.
    """
    overlap = cfg.overlap_collection
    collect_s = update_s = load = 0.0
    for cycle in range(cfg.cycles_per_epoch):
        if cycle == cfg.cycles_per_epoch - 1:
            # The paper's code refits MEP's density model once an epoch, on the buffer before the last cycle's episodes.
            learner.refit_sampler()
        tick = time.perf_counter()
        if cycle == 0 or not overlap:
            # The epoch's first batch restarts the collection streams; without overlap each batch
            # is collected here, with the policy of the end of the last cycle, as baselines does.
            seed = derive_seed(cfg.seed, epoch, COLLECTION_STREAM) if cycle == 0 else None
            batches.request(seed, background=overlap)
        learner.store(batches.result())
        if overlap and cycle + 1 < cfg.cycles_per_epoch:
            # The next cycle's episodes, collected during this cycle's updates: one cycle stale.
            batches.request(background=True)
        collect_s += time.perf_counter() - tick

        tick = time.perf_counter()
        for _ in range(cfg.updates_per_cycle):
            # The collecting process holds a core: one thread fewer until it is done, so that
            # the two never oversubscribe the cores and the updates get them all afterwards.
            threads = max(1, cfg.threads - 1) if batches.busy() else cfg.threads
            if threads != torch.get_num_threads():
                torch.set_num_threads(threads)
            learner.update()
        learner.agent.target_updater.step()
        update_s += time.perf_counter() - tick
        load += os.getloadavg()[0] / cfg.cycles_per_epoch
    return {"collect_s": collect_s, "update_s": update_s, "load_avg": load}


def prepare_run_dir(cfg: DictConfig, run_dir: str | Path) -> tuple[Path, bool]:
    """Creates ``run_dir``; returns it and whether the run resumes from its checkpoint.

    Args:
        cfg (DictConfig): the training config; reads ``resume``.
        run_dir (str or Path): the run's folder.

    Raises:
        ConfigError: ``run_dir`` holds a checkpoint and ``cfg.resume`` is false.
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if has_checkpoint(run_dir) and not cfg.resume:
        raise ConfigError(
            f"{run_dir} already holds a checkpoint: pass resume=true to continue that run, "
            "or choose another output directory (hydra.run.dir=...)"
        )
    return run_dir, cfg.resume and has_checkpoint(run_dir)


def train(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Trains DDPG+HER as configured by ``cfg`` (``conf/config.yaml``, composed with
    :func:`~torchrl_cebp.training.config.compose_config`); returns the CSV path.

    ``run_dir`` receives ``progress.csv`` (one row per epoch), ``checkpoint.pt`` (the previous epoch's
    beside it) and ``policy.pt`` (after each epoch), and ``best_policy.pt`` (the epoch with the highest test
    success so far). With ``cfg.resume`` the run continues after the checkpoint's epoch (the previous one's,
    when the newest does not load).

    Args:
        cfg (DictConfig): the composed training config.
        run_dir (str or Path): the run's folder.

    Raises:
        ConfigError: an invalid config, a checkpoint in ``run_dir`` without ``cfg.resume``, or a checkpoint of
            another run.
        RunFolderInUseError: another process is training in ``run_dir`` (it holds the folder's
            :class:`~torchrl_cebp.training.run_lock.RunFolderLock` for as long as it runs).
        UnreadableFileError: with ``cfg.resume``, neither checkpoint of ``run_dir`` loads.
    """
    validate_config(cfg)
    sampler = make_sampler(cfg)  # here, so that a bad sampler argument fails before the run folder is made
    with RunFolderLock(run_dir):  # before anything is written there: a second process on the folder is refused
        return _train_in_locked_folder(cfg, run_dir, sampler)


def _train_in_locked_folder(cfg: DictConfig, run_dir: str | Path, sampler: Sampler) -> Path:
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    run_dir, resuming = prepare_run_dir(cfg, run_dir)
    device = resolve_device(cfg.device)
    warn_if_bf16_is_emulated(cfg.precision, device)
    checkpoints = RunCheckpoints(run_dir)
    # Read before the envs start, so that a run none of whose checkpoints loads stops at once. The newest
    # checkpoint, or the previous epoch's if the newest does not load (the CSV then drops the later rows).
    state = checkpoints.load(map_location=device) if resuming else None

    test_env = make_env(cfg, episodes_per_cycle(cfg), device)
    dims = TaskDims.of(test_env)
    agent = make_agent(cfg, dims, device)
    optimizer = make_optimizer(cfg, agent.loss)
    replay, her = make_replay(cfg, sampler, test_env)
    learner = Learner(cfg, agent, optimizer, replay, her, sampler, device, ExplorationLog(test_env.distance_threshold))
    batches = make_training_collector(cfg, agent, dims)
    start_epoch, wall_before = 0, 0.0
    if state is not None:  # after every part is built: building one may draw from the restored random streams
        start_epoch, wall_before = restore_training_state(state, cfg, agent, optimizer, replay, learner.beta_scheduler)
    best_policy = BestPolicy(run_dir, resume=resuming)
    labels = {"replay": replay_layout(cfg), "replay_capacity": replay_capacity(cfg), "her_strategy": cfg.replay.strategy}
    log = EpochLog(run_dir, start_epoch, cfg.logger, labels=labels)
    run_start = time.perf_counter()

    progress = tqdm(range(start_epoch, cfg.epochs), initial=start_epoch, total=cfg.epochs, desc="epochs")
    for epoch in progress:
        epoch_start = time.perf_counter()
        timings = run_epoch(cfg, epoch, learner, batches)

        tick = time.perf_counter()
        test_env.set_seed(derive_seed(cfg.seed, epoch, TEST_STREAM))
        success = evaluate_success_rate(test_env, agent.policy, cfg.test_episodes * cfg.workers)
        epoch_s = time.perf_counter() - epoch_start
        env_steps = cfg.cycles_per_epoch * episodes_per_cycle(cfg) * dims.episode_steps
        wall_s = wall_before + time.perf_counter() - run_start
        log.write(epoch, {
            "test_success": success,
            **learner.epoch_means(),
            "stored_episodes": len(replay.storage) // dims.episode_steps,
            "env_steps_per_s": env_steps / epoch_s,
            **{key: timings[key] for key in ("collect_s", "update_s")},
            "test_s": time.perf_counter() - tick,
            "epoch_s": epoch_s,
            "wall_s": wall_s,
            # Above the runs' own thread count, something else shared the cores and inflated epoch_s.
            "load_avg": timings["load_avg"],
        })
        # The policy files first: a checkpoint then implies that they include its epoch.
        policy = policy_state(cfg, agent, epoch=epoch, test_success=success)
        save_policy(policy, run_dir)
        best_policy.offer(policy)
        checkpoints.save(training_state(epoch, wall_s, cfg, agent, optimizer, replay, learner.beta_scheduler))
        progress.set_postfix(success=f"{success:.3f}", steps_per_s=f"{env_steps / epoch_s:.0f}")
        tqdm.write(f"epoch {epoch:3d}  test success {success:.3f}  ({env_steps / epoch_s:.0f} env steps/s)")

    batches.close()
    test_env.close()
    return log.csv_path
