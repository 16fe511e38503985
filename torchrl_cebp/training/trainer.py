"""DDPG + HER training with any of the replay samplers, as in baselines' HER (readable top to bottom).

An epoch is ``cycles_per_epoch`` cycles; a cycle collects ``rollouts_per_cycle x workers``
whole episodes from a batched env, stores them, runs ``updates_per_cycle`` updates of
``batch_size x workers`` transitions, and moves the target networks. Each epoch ends with
deterministic test episodes, a CSV row and a checkpoint. With ``overlap_collection`` a worker
process collects the next cycle's episodes while this one's updates run.
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictSequential
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.envs import EnvBase, ParallelEnv
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.objectives import SoftUpdate
from tqdm import tqdm

from torchrl_cebp.agents import HERDDPGLoss, make_critic
from torchrl_cebp.envs import make_env_from_config
from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
from torchrl_cebp.samplers import PERSampler
from torchrl_cebp.training.checkpoint import (
    has_checkpoint,
    load_checkpoint,
    rng_state,
    save_checkpoint,
    set_rng_state,
)
from torchrl_cebp.training.config import (
    ConfigError,
    check_same_run,
    resolve_device,
    validate_config,
    warn_if_bf16_is_emulated,
)
from torchrl_cebp.training.metrics import EpochCsv, code_version, make_logger
from torchrl_cebp.training.rollouts import RolloutWorker, Rollouts, Seeds, make_policy

CSV_NAME = "progress.csv"


def derive_seed(*keys: int) -> int:
    """A 31-bit seed for one stream (e.g. ``(seed, epoch, stream)``), independent of the others."""
    return int(np.random.SeedSequence(list(keys)).generate_state(1)[0] >> 1)


class RelabelledTransitions:
    """Every transition of a batch of new episodes ``[n, T]``, its goal relabelled as the replay would.

    Baselines feeds its normaliser such relabelled transitions of each new batch of
    episodes, so the goal statistics cover the goals the networks are trained on
    (independently of how the sampler draws from the buffer). It relabels through the
    replay's own :meth:`HindsightRelabel.relabel`.

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


@torch.no_grad()
def evaluate_success_rate(env: EnvBase, policy: TensorDictSequential, n_episodes: int, episode_steps: int) -> float:
    """Success rate at the last step of ``n_episodes`` deterministic episodes on the batched ``env``."""
    successes = []
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        for _ in range(math.ceil(n_episodes / env.batch_size[0])):
            rollout = env.rollout(episode_steps, policy, break_when_any_done=False)
            successes.append(rollout["next", "is_success"][:, -1, 0])
    return torch.cat(successes)[:n_episodes].float().mean().item()


def make_task_env(cfg: DictConfig, **kwargs) -> EnvBase:
    """The configured task's env: ``cfg.env``'s task, goal space and robot; ``kwargs`` go to :func:`make_env`."""
    return make_env_from_config(cfg.env, **kwargs)


def make_batched_env(cfg: DictConfig, n_envs: int, device: torch.device | str = "cpu") -> EnvBase:
    """``n_envs`` simulations of the task: stepped in turn by one env, or one process each (``env_backend``)."""
    if cfg.env_backend == "parallel":
        return ParallelEnv(n_envs, functools.partial(make_task_env, cfg, device=device))
    return make_task_env(cfg, device=device, num_envs=n_envs)


def make_rollouts(cfg: DictConfig, dims: tuple[int, int, int], episode_steps: int) -> Rollouts:
    """The training episodes' env and a copy of the exploration policy, with its own noise generator."""
    _, explore = make_policy(
        *dims, cfg.agent.hidden, random_eps=cfg.agent.random_eps, noise_std=cfg.agent.noise_std,
        generator=torch.Generator(),
    )
    n_envs = cfg.rollouts_per_cycle * cfg.workers
    return Rollouts(make_batched_env(cfg, n_envs), explore, episode_steps, drop_keys=["agent_input"])


def sampling_spread(sampler: Sampler) -> dict[str, float]:
    """Effective fraction of stored episodes the sampler draws from, ``1 / (N sum p^2)``, when it exposes ``p``."""
    n = getattr(sampler, "n_episodes", 0)
    if not n or not hasattr(sampler, "probabilities"):
        return {}
    p = sampler.probabilities(torch.arange(n))
    return {"priority_ess_fraction": (1.0 / (n * p.square().sum())).item()}


def train(cfg: DictConfig, run_dir: str | Path) -> Path:
    """Trains DDPG+HER as configured by ``cfg`` (see ``conf/config.yaml``); returns the CSV path.

    ``run_dir`` receives ``progress.csv`` (one row per epoch) and ``checkpoint.pt``
    (after each epoch). With ``cfg.resume`` the run continues after the checkpoint's epoch.
    """
    validate_config(cfg)
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    sampler = instantiate(cfg.sampler)  # here, so that a bad sampler argument fails before the envs start
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    resuming = cfg.resume and has_checkpoint(run_dir)
    if has_checkpoint(run_dir) and not cfg.resume:
        raise ConfigError(
            f"{run_dir} already holds a checkpoint: pass resume=true to continue that run, "
            "or choose another output directory (hydra.run.dir=...)"
        )
    device = resolve_device(cfg.device)
    warn_if_bf16_is_emulated(cfg.precision, device)
    use_bf16 = cfg.precision == "bf16"

    # Environments: the training episodes come from a copy of the policy (in a worker process
    # with overlap_collection), the test episodes from this one. Both run on the CPU.
    n_envs = cfg.rollouts_per_cycle * cfg.workers
    spec_env = make_task_env(cfg)
    episode_steps = spec_env.max_episode_steps
    dims = (
        spec_env.observation_spec["observation"].shape[-1],
        spec_env.observation_spec["desired_goal"].shape[-1],
        spec_env.action_spec.shape[-1],
    )
    new_rollouts = functools.partial(make_rollouts, cfg, dims, episode_steps)
    rollouts = RolloutWorker(new_rollouts) if cfg.overlap_collection else new_rollouts()
    test_env = make_batched_env(cfg, n_envs, device)

    # Agent: the normaliser is shared by the policy and (outside the loss) the training batches.
    policy, exploration_policy = make_policy(*dims, cfg.agent.hidden)
    normalizer, actor = policy.to(device)
    critic = make_critic(dims[0] + dims[1], dims[2], cfg.agent.hidden).to(device)
    loss = HERDDPGLoss(actor, critic, gamma=1.0 - 1.0 / episode_steps, action_l2=cfg.agent.action_l2)
    target_updater = SoftUpdate(loss, tau=cfg.agent.tau)
    # Fused Adam: one kernel per step instead of a dozen per parameter group (~1 ms of 15 per update).
    actor_optim = torch.optim.Adam(loss.actor_network_params.values(True, True), lr=cfg.agent.lr_actor, fused=True)
    critic_optim = torch.optim.Adam(loss.value_network_params.values(True, True), lr=cfg.agent.lr_critic, fused=True)

    # Replay: whole episodes as rows, the configured sampler, HER relabelling at sampling time.
    her = HindsightRelabel(spec_env.compute_reward, future_p=cfg.replay.future_p, strategy=cfg.replay.strategy)
    # A generator of its own for every replay draw: TorchRL's PER falls back to numpy's unseeded global RNG without one.
    replay = make_replay_buffer(sampler, her, capacity=cfg.replay.capacity, batch_size=cfg.batch_size * cfg.workers,
                                generator=torch.Generator().manual_seed(derive_seed(cfg.seed, 3)))
    normalizer_feed = RelabelledTransitions(her)
    beta_scheduler = sampler.beta_scheduler() if isinstance(sampler, PERSampler) else None

    def collection_weights() -> dict[str, torch.Tensor]:
        return {key: value.detach().cpu() for key, value in exploration_policy.state_dict().items()}

    start_epoch, wall_before = 0, 0.0
    if resuming:
        state = load_checkpoint(run_dir, map_location=device)
        check_same_run(state["config"], cfg)
        loss.load_state_dict(state["loss"])
        normalizer.load_state_dict(state["normalizer"])
        actor_optim.load_state_dict(state["actor_optim"])
        critic_optim.load_state_dict(state["critic_optim"])
        replay.load_state_dict(state["replay"])
        if beta_scheduler is not None:
            # Checkpoints from before the scheduler kept the draw count in PER's own state.
            draws = state["replay"]["_sampler"].get("draws", 0)
            beta_scheduler.load_state_dict(state.get("beta_scheduler", {**beta_scheduler.state_dict(), "_step_cnt": draws}))
        # Restored last, so that building the agent above draws nothing from the restored stream.
        set_rng_state(state["rng"])
        start_epoch, wall_before = state["epoch"] + 1, state["wall_s"]
    csv_log = EpochCsv(run_dir / CSV_NAME, start_epoch)
    commit = code_version()
    logger = make_logger(cfg.logger, run_dir)
    run_start = time.perf_counter()

    progress = tqdm(range(start_epoch, cfg.epochs), initial=start_epoch, total=cfg.epochs, desc="epochs")
    for epoch in progress:
        epoch_start = time.perf_counter()
        # Each epoch starts from the current policy and reseeded env and exploration streams,
        # so a resumed run repeats an uninterrupted one, with or without overlap.
        rollouts.submit(collection_weights(), Seeds(derive_seed(cfg.seed, epoch, 0), derive_seed(cfg.seed, epoch, 2)))
        totals: dict[str, torch.Tensor] = defaultdict(float)
        collect_s = update_s = load = 0.0
        for cycle in range(cfg.cycles_per_epoch):
            tick = time.perf_counter()
            episodes = rollouts.result()
            replay.extend(episodes)
            normalizer.update(normalizer_feed(episodes))
            next_cycle = cycle + 1 < cfg.cycles_per_epoch
            if cfg.overlap_collection and next_cycle:
                # The next cycle's episodes, collected during this cycle's updates: one cycle stale.
                rollouts.submit(collection_weights())
            collect_s += time.perf_counter() - tick

            tick = time.perf_counter()
            for _ in range(cfg.updates_per_cycle):
                # The collecting worker holds a core: one thread fewer until it is done, so that
                # the two never oversubscribe the cores and the updates get them all afterwards.
                threads = max(1, cfg.threads - 1) if rollouts.busy() else cfg.threads
                if threads != torch.get_num_threads():
                    torch.set_num_threads(threads)
                batch = replay.sample().to(device)
                if beta_scheduler is not None:
                    beta_scheduler.step()
                normalizer(batch)
                normalizer(batch["next"])
                with torch.autocast(device.type, dtype=torch.bfloat16, enabled=use_bf16):
                    losses = loss(batch)
                actor_optim.zero_grad()
                critic_optim.zero_grad()
                (losses["loss_actor"] + losses["loss_value"]).backward()
                actor_optim.step()
                critic_optim.step()
                replay.update_tensordict_priority(batch)  # a no-op unless the sampler is PER
                for key in ("loss_actor", "loss_value", "action_l2"):
                    totals[key] += losses[key].detach()
                totals["q_mean"] += losses["pred_value"].mean()
                if "priority_weight" in batch.keys():
                    totals["is_weight_mean"] += batch["priority_weight"].mean()
                    totals["is_weight_min"] += batch["priority_weight"].min()
            target_updater.step()
            update_s += time.perf_counter() - tick
            load += os.getloadavg()[0] / cfg.cycles_per_epoch
            if not cfg.overlap_collection and next_cycle:
                rollouts.submit(collection_weights())

        if hasattr(sampler, "refit"):
            sampler.refit(replay.storage)

        tick = time.perf_counter()
        test_env.set_seed(derive_seed(cfg.seed, epoch, 1))
        success = evaluate_success_rate(test_env, policy, cfg.test_episodes * cfg.workers, episode_steps)
        test_s = time.perf_counter() - tick

        epoch_s = time.perf_counter() - epoch_start
        env_steps = cfg.cycles_per_epoch * n_envs * episode_steps
        n_updates = cfg.cycles_per_epoch * cfg.updates_per_cycle
        wall_s = wall_before + time.perf_counter() - run_start
        row = {
            "epoch": epoch,
            "test_success": success,
            **{key: (value / n_updates).item() for key, value in totals.items()},
            **sampling_spread(sampler),
            "stored_episodes": len(replay.storage) // episode_steps,
            "env_steps_per_s": env_steps / epoch_s,
            "collect_s": collect_s,
            "update_s": update_s,
            "test_s": test_s,
            "epoch_s": epoch_s,
            "wall_s": wall_s,
            # Above the runs' own thread count, something else shared the cores and inflated epoch_s.
            "load_avg": load,
        }
        csv_log.write({**row, "code_commit": commit})
        if logger is not None:
            for key, value in row.items():
                logger.log_scalar(key, value, step=epoch)
        save_checkpoint(
            {
                "epoch": epoch,
                "wall_s": wall_s,
                "config": OmegaConf.to_container(cfg, resolve=True),
                "loss": loss.state_dict(),
                "normalizer": normalizer.state_dict(),
                "actor_optim": actor_optim.state_dict(),
                "critic_optim": critic_optim.state_dict(),
                "replay": replay.state_dict(),
                **({"beta_scheduler": beta_scheduler.state_dict()} if beta_scheduler is not None else {}),
                "rng": rng_state(),
            },
            run_dir,
        )
        progress.set_postfix(success=f"{success:.3f}", steps_per_s=f"{env_steps / epoch_s:.0f}")
        tqdm.write(f"epoch {epoch:3d}  test success {success:.3f}  ({env_steps / epoch_s:.0f} env steps/s)")

    rollouts.close()
    test_env.close()
    spec_env.close()
    return run_dir / CSV_NAME
