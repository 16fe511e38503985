"""DDPG + HER with a CEBP replay sampler, in TorchRL's own DDPG loop.

The loop of TorchRL's ``sota-implementations/ddpg/ddpg.py`` as it is: a collector yields frames,
``replay_buffer.extend(frames)``, then ``utd_ratio`` updates per frame of sample, loss, optimiser
step and target update. Our pieces come in through ``make_*`` calls only: the env, the agent
(actor, critic, HER's DDPG loss and soft update, from ``torchrl_cebp/conf/config.yaml``), the sampler (``torchrl_cebp/conf/sampler/``)
and a stock TorchRL buffer whose ``EpisodeWriter`` assembles the collector's frames into episodes,
which HER relabels as they are drawn.

    python examples/ddpg_her.py --help
    python examples/ddpg_her.py --sampler cebp --env push --total-frames 200000
"""
from __future__ import annotations

import argparse

import torch
from omegaconf import DictConfig
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.data import TensorDictReplayBuffer
from torchrl.envs.utils import ExplorationType

from torchrl_cebp.envs import compute_reward_of
from torchrl_cebp.replay import EpisodeWriter, HindsightRelabel, make_replay_buffer
from torchrl_cebp.training.config import CONFIG_DIR, compose_config
from torchrl_cebp.training.builders import (
    TaskDims, make_agent, make_env, make_optimizer, make_sampler, replay_capacity,
)
from torchrl_cebp.training.trainer import RelabelledTransitions, beta_annealing



def config_choices(group: str) -> list[str]:
    """The configs of a group of ``torchrl_cebp/conf/`` (e.g. ``"sampler"``), so that a wrong name is refused with the right ones."""
    return sorted(path.stem for path in (CONFIG_DIR / group).glob("*.yaml"))


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="push", choices=config_choices("env"), help="a config of torchrl_cebp/conf/env/")
    parser.add_argument("--sampler", default="cebp", choices=config_choices("sampler"), help="a config of torchrl_cebp/conf/sampler/")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--envs", type=int, default=2, help="simulations the collector steps, as one batched env")
    parser.add_argument("--frames-per-batch", type=int, default=100)
    parser.add_argument("--total-frames", type=int, default=100_000)
    parser.add_argument("--utd-ratio", type=float, default=0.4, help="updates per collected frame (HER: 40 per 100)")
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--buffer-size", type=int, default=1_000_000, help="capacity in transitions")
    parser.add_argument("--refit-frames", type=int, default=5_000,
                        help="frames between MEP's refits of its density model (HER's epoch at two envs)")
    args = parser.parse_args(argv)
    for name in ("envs", "frames_per_batch", "total_frames", "batch_size", "buffer_size", "refit_frames"):
        if getattr(args, name) <= 0:  # a collector of no frames would end at once, having printed nothing
            parser.error(f"--{name.replace('_', '-')}={getattr(args, name)}: must be a positive integer")
    if args.utd_ratio < 0:
        parser.error(f"--utd-ratio={args.utd_ratio}: must be 0 or more")
    return args


def project_config(args: argparse.Namespace) -> DictConfig:
    """The package's config (``torchrl_cebp/conf/``) for this env and sampler: the agent's and HER's settings, stated
    once there."""
    return compose_config(f"env={args.env}", f"sampler={args.sampler}", f"seed={args.seed}",
                          f"replay.capacity={args.buffer_size}", f"batch_size={args.batch_size}")


def main(argv: list[str] | None = None) -> tuple[TensorDictReplayBuffer, TensorDict]:
    """Trains, printing progress; returns the replay buffer and the losses of the last batch's updates."""
    args = parse_args(argv)
    cfg = project_config(args)
    torch.manual_seed(args.seed)

    train_env = make_env(cfg, args.envs)
    train_env.set_seed(args.seed)
    dims = TaskDims.of(train_env)
    agent = make_agent(cfg, dims)
    optimizer = make_optimizer(cfg, agent.loss)
    collector = Collector(train_env, agent.exploration, frames_per_batch=args.frames_per_batch,
                          total_frames=args.total_frames, exploration_type=ExplorationType.RANDOM,
                          auto_register_policy_transforms=False)

    sampler = make_sampler(cfg)
    her = HindsightRelabel(compute_reward_of(train_env), future_p=cfg.replay.future_p, strategy=cfg.replay.strategy)
    replay_buffer = make_replay_buffer(sampler, her, capacity=replay_capacity(cfg), batch_size=args.batch_size,
                                       writer=EpisodeWriter(dims.episode_steps))
    # HER's normaliser learns from the relabelled transitions of each new episode, as baselines' does.
    normalizer_feed = RelabelledTransitions(her)
    beta_scheduler = beta_annealing(sampler)  # PER's beta, 0.4 -> 1; None for the other samplers
    refit = getattr(sampler, "refit", None)  # MEP re-ranks the stored episodes on a schedule; the others need nothing

    def update(batch: TensorDict) -> TensorDict:
        agent.normalizer(batch)  # the actor and critic read the normalised observation and (relabelled) goal
        agent.normalizer(batch["next"])
        td_loss = agent.loss(batch)
        optimizer.zero_grad(set_to_none=True)
        (td_loss["loss_actor"] + td_loss["loss_value"]).backward()
        optimizer.step()
        agent.target_updater.step()
        return td_loss.select("loss_actor", "loss_value").detach()

    num_updates = int(args.frames_per_batch * args.utd_ratio)
    collected_frames = 0
    tds = TensorDict()
    for tensordict in collector:
        collector.update_policy_weights_()
        collected_frames += tensordict.numel()
        # Frames in, whole episodes stored: the index is -1 for the frames of episodes that have not ended.
        index = replay_buffer.extend(tensordict)
        ended = torch.unique(index[index >= 0] // dims.episode_steps)
        if ended.numel():
            agent.normalizer.update(normalizer_feed(replay_buffer.storage[ended]))
        if refit is not None and collected_frames % args.refit_frames < tensordict.numel():
            refit(replay_buffer.storage)

        # No episode has ended before the first episode_steps frames: nothing to draw yet.
        if len(replay_buffer):
            losses = []
            for _ in range(num_updates):
                sampled_tensordict = replay_buffer.sample()
                losses.append(update(sampled_tensordict))
                replay_buffer.update_tensordict_priority(sampled_tensordict)  # a no-op unless the sampler is PER
                if beta_scheduler is not None:
                    beta_scheduler.step()
            tds = torch.stack(losses)
            print(f"frames {collected_frames}/{args.total_frames}  episodes {replay_buffer.storage.shape[0]}  "
                  f"loss_actor {tds['loss_actor'].mean():.4f}  loss_value {tds['loss_value'].mean():.4f}", flush=True)

    collector.shutdown()
    if not train_env.is_closed:
        train_env.close()
    return replay_buffer, tds


if __name__ == "__main__":
    main()
