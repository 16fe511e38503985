"""What each prioritised sampler would replay from one run's stored episodes, epoch by epoch.

Every sampler named is fed the run's episodes in the order the run wrote them, a cycle's episodes per write, with
the run's replay layout (per-worker replay gives each emulated worker its own episodes) and MEP's refit where the
trainer makes it, before each epoch's last cycle is stored. After each epoch's episodes it reads the draw's
probabilities and prints, per sampler:

- ``ess``: the effective fraction of stored episodes the draw uses, ``1 / (N sum p^2)`` (the CSVs'
  ``priority_ess_fraction``);
- ``moved``: the share of draws that land on an episode whose object moved more than ``--moved-cm`` (its share
  of the stored episodes is HER's, which draws uniformly);
- ``touched``: the share on an episode where a finger pad felt something (on robot A nearly all: its pads feel the
  table);
- ``reached``: the share on an episode that ended at its own goal (its last reward is 0, not -1);
- ``top1%``: the share on the 1% of stored episodes the sampler ranks highest;
- ``moved weighted`` and ``top1% weighted``: those episodes' expected share of the critic's summed sample weights:
  draws scaled by the sampler's importance-sampling weights, each worker's over its own episodes, each batch divided
  by its largest (the draw's own share for a sampler without weights). It is a share of the weights, not of the loss,
  which also scales with each transition's TD error. Only the critic's loss is weighted: the actor's follows the draw.

Which episodes a run stored depends on what it replayed, so a run of each sampler gives a different buffer; run it on
several. PER is left out: its priorities are TD errors, which need the run's critic at each epoch.

    python scripts/compare_draws.py runs/push-standard/ebp/paper-per_worker/seed0 --out draws.png
"""

from __future__ import annotations

import argparse
import copy
import csv
import sys
from pathlib import Path

import torch
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import InterpolationKeyError
from tensordict import TensorDictBase
from torchrl.data.replay_buffers.samplers import Sampler
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp.replay import HindsightRelabel, episode_lengths, make_replay_buffer
from torchrl_cebp.replay.episodes import valid_steps
from torchrl_cebp.samplers import EpisodePrioritySampler, PerWorkerSampler
from torchrl_cebp.training.builders import episodes_per_cycle, make_sampler, replay_capacity
from torchrl_cebp.training.checkpoint import load_checkpoint, stored_episodes
from torchrl_cebp.training.trainer import sampling_spread

REPO = Path(__file__).resolve().parents[1]
SAMPLER_CONFIGS = REPO / "conf" / "sampler"
METRICS = ("ess", "moved", "touched", "reached", "top1%", "moved weighted", "top1% weighted")
# Nothing here draws a batch, so HER never computes a reward.
REWARD_FREE = HindsightRelabel(lambda achieved, goal: torch.zeros(*achieved.shape[:-1], 1))


def episode_priority_samplers() -> list[str]:
    """The sampler configs whose draw is by episode priority, which a stored buffer alone decides (not PER's)."""
    return sorted(path.stem for path in SAMPLER_CONFIGS.glob("*.yaml")
                  if issubclass(get_class(OmegaConf.load(path)._target_), EpisodePrioritySampler))


def sampler_config(run_cfg: DictConfig, name: str) -> DictConfig:
    """The run's config with ``sampler`` swapped for ``conf/sampler/<name>.yaml``, resolved against the run's env.

    The run's own sampler keeps the run's settings (a temperature sweep's, say), not the config file's defaults.
    """
    cfg = copy.deepcopy(run_cfg)
    sampler = OmegaConf.load(SAMPLER_CONFIGS / f"{name}.yaml")
    if sampler._target_ != run_cfg.sampler._target_:
        cfg.sampler = sampler
    try:
        OmegaConf.resolve(cfg)
    except InterpolationKeyError as error:
        raise SystemExit(f"sampler {name!r} needs a setting this run's saved config lacks "
                         f"(it predates it): {error.msg}") from None
    return cfg


def episode_features(episodes: TensorDictBase, moved_m: float) -> dict[str, torch.Tensor]:
    """Per episode, over its valid steps: did its object leave its start by more than ``moved_m``, did a pad touch
    anything, and did it end at its goal (its last reward 0, not -1)."""
    lengths = episode_lengths(episodes)
    valid = valid_steps(lengths, episodes.shape[1])
    distance = torch.linalg.vector_norm(episodes["next", "achieved_goal"] - episodes["achieved_goal"][:, :1], dim=-1)
    moved = (distance * valid).amax(dim=-1) > moved_m
    touched = ((episodes["next", "touch"] > 0).any(dim=-1) & valid).any(dim=-1)
    last_reward = episodes["next", "reward"].squeeze(-1).gather(1, (lengths - 1).unsqueeze(-1)).squeeze(-1)
    return {"moved": moved, "touched": touched, "reached": last_reward == 0}


def draw_shares(probabilities: torch.Tensor, features: dict[str, torch.Tensor],
                sample_weight: torch.Tensor | None = None) -> dict[str, float]:
    """The shares of one draw over the stored episodes that land on each feature's episodes and on the top 1%, and
    the moved and top 1% episodes' shares of the critic's ``sample_weight`` (the draw's own shares without one)."""
    p = probabilities.double() / probabilities.double().sum()
    top = p.topk(max(p.numel() // 100, 1)).indices
    weighed = p if sample_weight is None else sample_weight.double() / sample_weight.double().sum()
    return {**{name: p[episodes].sum().item() for name, episodes in features.items()}, "top1%": p[top].sum().item(),
            "moved weighted": weighed[features["moved"]].sum().item(), "top1% weighted": weighed[top].sum().item()}


def expected_batch_weights(probabilities: torch.Tensor, weights: torch.Tensor, batch: int) -> torch.Tensor:
    """Each episode's expected part of one sampler's batch of summed IS weights, each batch divided by its largest.

    A draw of episode ``i`` counts ``w_i / max(w_i, M)``, where ``M`` is the largest weight among the batch's other
    ``batch - 1`` draws, ``P(M <= m) = F(m)^(batch - 1)`` with ``F(m)`` the draw's mass on weights up to ``m``. So
    the episode's part is ``p_i w_i E[1 / max(w_i, M)]``: the division lifts the episodes drawn often (small
    weights) above their ``p_i w_i``.
    """
    values, which = torch.unique(weights.double(), sorted=True, return_inverse=True)
    mass = torch.zeros_like(values).index_add_(0, which, probabilities.double())
    below_or_at = mass.cumsum(0).clamp(max=1.0)
    largest_is = below_or_at ** (batch - 1) - (below_or_at - mass).clamp(min=0.0) ** (batch - 1)
    above = (largest_is / values).flip(0).cumsum(0).flip(0) - largest_is / values
    expected_inverse = below_or_at ** (batch - 1) / values + above
    return probabilities.double() * weights.double() * expected_inverse[which]


def critic_sample_weight(sampler: Sampler, storage: Storage, stored: int, batch: int) -> torch.Tensor | None:
    """Each stored episode's expected share of the critic's summed sample weights, with each worker's IS weights over
    its own episodes and batches of ``batch`` draws; ``None`` for a sampler that weights nothing."""
    if isinstance(sampler, PerWorkerSampler):
        shards = [(view.global_rows(torch.arange(view.shape[0])), shard)
                  for view, shard in zip(sampler.worker_views(storage), sampler.samplers)]
    else:
        shards = [(torch.arange(stored), sampler)]
    part = torch.zeros(stored, dtype=torch.float64)
    for rows, shard in shards:
        local = shard.probabilities(torch.arange(rows.numel()))
        weights = shard.importance_weights(local, shard.n_episodes)
        if weights is None:
            return None
        part[rows] = expected_batch_weights(local, weights, batch)
    return part / part.sum()


def replay_as_written(run_cfg: DictConfig, episodes: TensorDictBase, name: str,
                      features: dict[str, torch.Tensor]) -> list[dict[str, str | int | float]]:
    """The ``METRICS`` of sampler ``name`` after each epoch, fed ``episodes`` as the run wrote them."""
    cfg = sampler_config(run_cfg, name)
    sampler = make_sampler(cfg)
    replay = make_replay_buffer(sampler, REWARD_FREE, capacity=replay_capacity(cfg), batch_size=1)
    per_cycle, cycles = episodes_per_cycle(cfg), cfg.cycles_per_epoch
    per_epoch = per_cycle * cycles
    batch = cfg.batch_size if isinstance(sampler, PerWorkerSampler) else cfg.batch_size * cfg.workers
    rows = []
    for epoch in range(episodes.shape[0] // per_epoch):
        for cycle in range(cycles):
            if cycle == cycles - 1 and hasattr(sampler, "refit"):  # where the trainer refits MEP
                sampler.refit(replay.storage)
            start = epoch * per_epoch + cycle * per_cycle
            replay.extend(episodes[start:start + per_cycle])
        stored = (epoch + 1) * per_epoch
        probabilities = sampler.probabilities(torch.arange(stored))
        shares = draw_shares(probabilities, {key: value[:stored] for key, value in features.items()},
                             critic_sample_weight(sampler, replay.storage, stored, batch))
        rows.append({"sampler": name, "epoch": epoch, "episodes": stored,
                     "ess": sampling_spread(sampler)["priority_ess_fraction"], **shares})
    return rows


def episodes_as_written(run_dir: Path) -> tuple[DictConfig, TensorDictBase]:
    """The run's config and every episode its checkpoint stores, in the order written, none overwritten."""
    state = load_checkpoint(run_dir)
    cfg = OmegaConf.create(state["config"])
    episodes, overwritten = stored_episodes(state)
    if overwritten:
        raise SystemExit(f"{run_dir}: its buffer wrapped ({overwritten} episodes overwritten); only the draws from "
                         "a buffer that still holds every episode can be replayed")
    written = (state["epoch"] + 1) * cfg.cycles_per_epoch * episodes_per_cycle(cfg)
    if episodes.shape[0] != written:
        raise SystemExit(f"{run_dir}: its buffer holds {episodes.shape[0]} episodes, where its {state['epoch'] + 1} "
                         f"epochs of {cfg.cycles_per_epoch} cycles wrote {written}")
    return cfg, episodes


def plot(rows: list[dict[str, str | int | float]], out: Path, title: str) -> None:
    """One panel per metric, the epochs along x, one line per sampler."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = 4
    figure, grid = plt.subplots(-(-(len(METRICS) + 1) // columns), columns, figsize=(3.4 * columns, 6.4),
                                constrained_layout=True)
    axes, legend_axis = grid.flat[:len(METRICS)], grid.flat[-1]
    for name in dict.fromkeys(row["sampler"] for row in rows):
        mine = [row for row in rows if row["sampler"] == name]
        for axis, metric in zip(axes, METRICS):
            axis.plot([row["epoch"] for row in mine], [row[metric] for row in mine], marker=".", label=name)
    for axis, metric in zip(axes, METRICS):
        axis.set(title=metric, xlabel="epoch (its episodes stored)", ylim=(0, 1.02))
    legend_axis.axis("off")
    legend_axis.legend(*axes[0].get_legend_handles_labels(), loc="center")
    figure.suptitle(title)
    figure.savefig(out, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path, help="a run folder with a checkpoint.pt")
    parser.add_argument("--samplers", nargs="+", default=["her", "cebp_initial", "cebp", "ebp", "mep"],
                        help="sampler configs of conf/sampler/ to compare (default: %(default)s)")
    parser.add_argument("--moved-cm", type=float, default=1.0,
                        help="an object moved when it left its start by more than this (default: %(default)s)")
    parser.add_argument("--csv", type=Path, help="also write the rows to this CSV")
    parser.add_argument("--out", type=Path, help="also draw the metrics over the epochs to this image")
    args = parser.parse_args()
    allowed = episode_priority_samplers()
    for name in args.samplers:
        if name not in allowed:
            parser.error(f"--samplers: {name!r} is not a sampler config that draws by episode priority; choose from "
                         f"{', '.join(allowed)}")
    run_cfg, episodes = episodes_as_written(args.run_dir)
    features = episode_features(episodes, args.moved_cm / 100)
    rows = []
    for name in args.samplers:
        print(f"[draws] {name}", file=sys.stderr, flush=True)
        rows += replay_as_written(run_cfg, episodes, name, features)
    print(f"episodes of {args.run_dir} ({run_cfg.sampler._target_.rsplit('.', 1)[-1]}'s run)")
    widths = {metric: max(len(metric) + 2, 9) for metric in METRICS}
    print(f"{'sampler':<14}{'epoch':>6}{'episodes':>10}" + "".join(f"{m:>{widths[m]}}" for m in METRICS))
    for row in rows:
        print(f"{row['sampler']:<14}{row['epoch']:>6}{row['episodes']:>10}" + "".join(f"{row[m]:>{widths[m]}.3f}" for m in METRICS))
    if args.csv:
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    if args.out:
        plot(rows, args.out, f"Draws from the episodes of {args.run_dir}")


if __name__ == "__main__":
    main()
