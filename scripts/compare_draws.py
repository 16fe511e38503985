"""What each prioritised sampler would replay from one run's stored episodes, epoch by epoch.

Every sampler named is fed the run's episodes in the order the run wrote them, a cycle's episodes per write, with
the run's replay layout (per-worker replay gives each emulated worker its own episodes) and MEP's refit where the
trainer makes it, before each epoch's last cycle is stored. After each epoch's episodes it reads the draw's
probabilities ``p`` over the ``N`` stored episodes and prints, per sampler:

- ``ess``: the effective fraction of stored episodes the draw uses, ``1 / (N sum p^2)`` (the CSVs'
  ``priority_ess_fraction``);
- ``kl``: the draw's KL divergence from uniform, ``sum p log(N p)`` in nats (0 for a uniform draw, ``log N`` at most);
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
- ``is_mean`` and ``is_ess``: the IS weights of a batch of ``--is-batch`` draws (each worker's own batch under
  per-worker replay), as the sampler's ``importance_weights`` gives them (``(N p)^-beta`` over the batch's largest):
  their mean, and their effective sample size as a fraction of the batch, ``(sum w)^2 / (batch sum w^2)``. Both are
  1 for a sampler without weights. ``is_mean`` is its exact expectation under the draw; ``is_ess`` is the average
  over ``--is-batches`` batches drawn with ``p`` from a generator seeded with ``--seed``, the same for every sampler.

``--temperatures`` adds the paper-form CEBP (``torchrl_cebp/conf/sampler/cebp.yaml``) at each sigmoid temperature ``T``, each
labelled ``cebp_T<T>``, beside the ``--samplers``, and ``--summary`` draws ``ess``, ``kl``, ``moved``, ``is_mean``
and ``is_ess`` after the last epoch against ``T`` on a log axis, with each of the ``--samplers`` as a horizontal
line: the temperature ablation's draws, on episodes that are the same for every ``T``.

Which episodes a run stored depends on what it replayed, so a run of each sampler gives a different buffer; run it on
several. PER is left out: its priorities are TD errors, which need the run's critic at each epoch.

    python scripts/compare_draws.py runs/push-standard/ebp/paper-per_worker/seed0 --out draws.png
    python scripts/compare_draws.py runs/push-standard-temperature/cebp_T5/paper-per_worker/seed0 \\
        --samplers her cper cebp_initial --temperatures 0.001 0.01 0.1 1 5 \\
        --csv draws.csv --out draws.png --summary draws_by_temperature.png
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
from torchrl_cebp.replay.samplers import EpisodePrioritySampler, PerWorkerSampler
from torchrl_cebp.training.builders import episodes_per_cycle, make_sampler, replay_capacity
from torchrl_cebp.training.checkpoint import load_checkpoint, stored_episodes
from torchrl_cebp.training.config import CONFIG_DIR
from torchrl_cebp.training.trainer import sampling_spread

SAMPLER_CONFIGS = CONFIG_DIR / "sampler"
METRICS = ("ess", "kl", "moved", "touched", "reached", "top1%", "moved weighted", "top1% weighted", "is_mean",
           "is_ess")
# The temperature ablation's question: how concentrated each T's draw is, on what, and what its IS weights undo.
SUMMARY_METRICS = ("ess", "kl", "moved", "is_mean", "is_ess")
UNBOUNDED_METRICS = {"kl"}  # up to log N; every other metric is a fraction
# Nothing here draws a batch, so HER never computes a reward.
REWARD_FREE = HindsightRelabel(lambda achieved, goal: torch.zeros(*achieved.shape[:-1], 1))


def episode_priority_samplers() -> list[str]:
    """The sampler configs whose draw is by episode priority, which a stored buffer alone decides (not PER's)."""
    return sorted(path.stem for path in SAMPLER_CONFIGS.glob("*.yaml")
                  if issubclass(get_class(OmegaConf.load(path)._target_), EpisodePrioritySampler))


def sampler_config(run_cfg: DictConfig, name: str) -> DictConfig:
    """The run's config with ``sampler`` swapped for ``torchrl_cebp/conf/sampler/<name>.yaml``, resolved against the run's env.

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


def temperature_label(temperature: float) -> str:
    """The label of the paper-form CEBP at sigmoid temperature ``temperature``: ``cebp_T0.01``, ``cebp_T5``."""
    return f"cebp_T{temperature:g}"


def temperature_config(run_cfg: DictConfig, temperature: float) -> DictConfig:
    """The run's config with the paper-form CEBP (``torchrl_cebp/conf/sampler/cebp.yaml``) at sigmoid temperature ``temperature``."""
    cfg = sampler_config(run_cfg, "cebp")
    cfg.sampler.temperature = temperature
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


def kl_from_uniform(probabilities: torch.Tensor) -> float:
    """The draw's KL divergence from the uniform draw over its ``N`` episodes, ``sum p log(N p)``, in nats."""
    p = probabilities.double() / probabilities.double().sum()
    return torch.special.xlogy(p, p * p.numel()).sum().item()


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


def importance_weight_spread(sampler: Sampler, batch: int, batches: int, seed: int) -> dict[str, float]:
    """The mean and effective sample size fraction, ``(sum w)^2 / (batch sum w^2)``, of the IS weights ``w`` of a batch
    of ``batch`` draws, as the sampler's ``importance_weights`` gives them (each worker's over its own episodes and
    draws), averaged over the workers; both 1 for a sampler that weights nothing.

    The mean is its exact expectation under the draw; the effective size is averaged over ``batches`` batches drawn
    with the sampler's probabilities from a generator seeded with ``seed``. The effective size does not change when
    a batch's weights are all scaled alike, so the weights of every stored episode serve each batch, whatever the
    batch's own normalisation.
    """
    shards = sampler.samplers if isinstance(sampler, PerWorkerSampler) else [sampler]
    generator = torch.Generator().manual_seed(seed)
    means, spreads = [], []
    for shard in shards:
        p = shard.probabilities(torch.arange(shard.n_episodes)).double()
        weights = shard.importance_weights(p, shard.n_episodes)
        if weights is None:
            return {"is_mean": 1.0, "is_ess": 1.0}
        means.append(expected_batch_weights(p, weights, batch).sum())
        rows = torch.multinomial(p, batch * batches, replacement=True, generator=generator).view(batches, batch)
        w = weights.double()[rows]
        spreads.append((w.sum(1).square() / (batch * w.square().sum(1))).mean())
    return {"is_mean": torch.stack(means).mean().item(), "is_ess": torch.stack(spreads).mean().item()}


def replay_as_written(cfg: DictConfig, label: str, episodes: TensorDictBase, features: dict[str, torch.Tensor],
                      is_batch: int, is_batches: int, seed: int) -> list[dict[str, str | int | float]]:
    """The ``METRICS`` of ``cfg``'s sampler, labelled ``label``, after each epoch, fed ``episodes`` as the run wrote
    them, with its IS weights' spread over batches of ``is_batch`` (:func:`importance_weight_spread`)."""
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
        metrics = {"ess": sampling_spread(sampler)["priority_ess_fraction"], "kl": kl_from_uniform(probabilities),
                   **draw_shares(probabilities, {key: value[:stored] for key, value in features.items()},
                                 critic_sample_weight(sampler, replay.storage, stored, batch)),
                   **importance_weight_spread(sampler, is_batch, is_batches, seed)}
        rows.append({"sampler": label, "epoch": epoch, "episodes": stored, **{m: metrics[m] for m in METRICS}})
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


def panels(metrics: tuple[str, ...]):
    """A figure with one panel per metric, four a row, and the panel after them for the legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = 4
    lines = -(-(len(metrics) + 1) // columns)
    figure, grid = plt.subplots(lines, columns, figsize=(3.4 * columns, 3.2 * lines), constrained_layout=True)
    for axis in grid.flat[len(metrics):]:
        axis.axis("off")
    return figure, grid.flat[:len(metrics)], grid.flat[len(metrics)]


def finish(figure, axes, legend_axis, metrics: tuple[str, ...], xlabel: str, title: str, out: Path) -> None:
    """Titles and scales each metric's panel (the fractions from 0 to 1; ``kl`` from 0 on a log scale, linear below
    0.001, where a concentrated draw's KL would flatten a nearly uniform one's), draws the legend, saves."""
    for axis, metric in zip(axes, metrics):
        axis.set(title=metric, xlabel=xlabel)
        if metric in UNBOUNDED_METRICS:
            axis.set_yscale("symlog", linthresh=1e-3)
        axis.set_ylim(0, None if metric in UNBOUNDED_METRICS else 1.02)
    legend_axis.legend(*axes[0].get_legend_handles_labels(), loc="center")
    figure.suptitle(title)
    figure.savefig(out, dpi=110)


def plot(rows: list[dict[str, str | int | float]], out: Path, title: str) -> None:
    """One panel per metric, the epochs along x, one line per sampler."""
    figure, axes, legend_axis = panels(METRICS)
    for name in dict.fromkeys(row["sampler"] for row in rows):
        mine = [row for row in rows if row["sampler"] == name]
        for axis, metric in zip(axes, METRICS):
            axis.plot([row["epoch"] for row in mine], [row[metric] for row in mine], marker=".", label=name)
    finish(figure, axes, legend_axis, METRICS, "epoch (its episodes stored)", title, out)


def plot_against_temperature(rows: list[dict[str, str | int | float]], temperatures: dict[str, float], out: Path,
                             title: str) -> None:
    """One panel per ``SUMMARY_METRICS`` after the last epoch: the paper-form CEBP against its temperature on a log
    axis, and every other sampler as a horizontal line."""
    last = max(row["epoch"] for row in rows)
    final = {row["sampler"]: row for row in rows if row["epoch"] == last}
    ladder = sorted(temperatures, key=temperatures.get)
    references = [name for name in final if name not in temperatures]
    figure, axes, legend_axis = panels(SUMMARY_METRICS)
    for axis, metric in zip(axes, SUMMARY_METRICS):
        axis.plot([temperatures[name] for name in ladder], [final[name][metric] for name in ladder], marker="o",
                  color="black", label="cebp (paper form) at T")
        for colour, name in enumerate(references):
            axis.axhline(final[name][metric], color=f"C{colour}", linestyle="--", label=name)
        axis.set_xscale("log")
    finish(figure, axes, legend_axis, SUMMARY_METRICS, "sigmoid temperature T",
           f"{title}, after epoch {last} ({final[ladder[0]]['episodes']} episodes)", out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path, help="a run folder with a checkpoint.pt")
    parser.add_argument("--samplers", nargs="+", default=["her", "cebp_initial", "cebp", "ebp", "mep"],
                        help="sampler configs of torchrl_cebp/conf/sampler/ to compare (default: %(default)s)")
    parser.add_argument("--temperatures", nargs="+", type=float, default=[], metavar="T",
                        help="also compare the paper-form CEBP (torchrl_cebp/conf/sampler/cebp.yaml) at each of these sigmoid "
                             "temperatures, labelled cebp_T<T> (default: none)")
    parser.add_argument("--is-batch", type=int, default=256,
                        help="draws per batch (per worker, under per-worker replay) for is_mean and is_ess "
                             "(default: %(default)s)")
    parser.add_argument("--is-batches", type=int, default=100,
                        help="seeded batches that is_ess averages over (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seeds the batches of is_ess (default: %(default)s)")
    parser.add_argument("--moved-cm", type=float, default=1.0,
                        help="an object moved when it left its start by more than this (default: %(default)s)")
    parser.add_argument("--csv", type=Path, help="also write the rows to this CSV")
    parser.add_argument("--out", type=Path, help="also draw the metrics over the epochs to this image")
    parser.add_argument("--summary", type=Path,
                        help="also draw ess, kl, moved, is_mean and is_ess after the last epoch against --temperatures "
                             "to this image, the --samplers as horizontal lines")
    args = parser.parse_args(argv)
    allowed = episode_priority_samplers()
    for name in args.samplers:
        if name not in allowed:
            parser.error(f"--samplers: {name!r} is not a sampler config that draws by episode priority; choose from "
                         f"{', '.join(allowed)}")
    for temperature in args.temperatures:
        if not temperature > 0:
            parser.error(f"--temperatures: {temperature:g} is not a sigmoid temperature: each must be positive")
    temperatures = {temperature_label(temperature): temperature for temperature in args.temperatures}
    if len(temperatures) != len(args.temperatures):
        parser.error(f"--temperatures: {' '.join(f'{t:g}' for t in args.temperatures)} names a temperature twice")
    if args.summary and not temperatures:
        parser.error("--summary draws the metrics against --temperatures: name at least one")
    for name, value in (("--is-batch", args.is_batch), ("--is-batches", args.is_batches)):
        if value < 1:
            parser.error(f"{name}: {value} is not a number of draws: it must be at least 1")
    run_cfg, episodes = episodes_as_written(args.run_dir)
    features = episode_features(episodes, args.moved_cm / 100)
    configs = {**{name: sampler_config(run_cfg, name) for name in args.samplers},
               **{label: temperature_config(run_cfg, temperature) for label, temperature in temperatures.items()}}
    rows = []
    for label, cfg in configs.items():
        print(f"[draws] {label}", file=sys.stderr, flush=True)
        rows += replay_as_written(cfg, label, episodes, features, args.is_batch, args.is_batches, args.seed)
    print(f"episodes of {args.run_dir} ({run_cfg.sampler._target_.rsplit('.', 1)[-1]}'s run); is_mean exact, is_ess "
          f"over {args.is_batches} batches of {args.is_batch} seeded with {args.seed}")
    widths = {metric: max(len(metric) + 2, 9) for metric in METRICS}
    print(f"{'sampler':<14}{'epoch':>6}{'episodes':>10}" + "".join(f"{m:>{widths[m]}}" for m in METRICS))
    for row in rows:
        print(f"{row['sampler']:<14}{row['epoch']:>6}{row['episodes']:>10}" + "".join(f"{row[m]:>{widths[m]}.3f}" for m in METRICS))
    if args.csv:
        with args.csv.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=[*rows[0], "temperature"])
            writer.writeheader()
            writer.writerows({**row, "temperature": temperatures.get(row["sampler"], "")} for row in rows)
    title = f"Draws from the episodes of {args.run_dir}"
    if args.out:
        plot(rows, args.out, title)
    if args.summary:
        plot_against_temperature(rows, temperatures, args.summary, title)


if __name__ == "__main__":
    main()
