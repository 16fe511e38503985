"""This checkout's replay against another commit's, and against TorchRL's writer, in one process.

Both packages load into one process (the other commit's renamed ``torchrl_cebp_before``), and for each sampler the
two buffers, filled with the same FetchPush-shaped episodes, take turns: a draw of 256 with 'future' HER
relabelling, a draw right after a write (what a training loop sees), and the write of one 50-step episode. Taking
turns puts a shared machine's load drift on both alike; swapping which goes first each turn does the same for the
warmth of the code the second one finds. MEP is refitted once after the fill, so that its writes rank against a
fitted mixture as in training. The last column divides a write by TorchRL's own ``HERReplayBuffer`` write
of the same episode, timed in the same turns.

    .venv/bin/python benchmarks/replay_versions.py --before 2bcbedd --episodes 20000 --repeats 300
"""
from __future__ import annotations

import argparse
import itertools
import math
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import torch

from _peers import (
    BATCH_SIZE, FUTURE_P, build_torchrl_her, elapsed_ms, episodes_to_tensordict, in_turn_order, make_episodes,
    our_samplers, sparse_reward,
)

ROOT = Path(__file__).resolve().parents[1]
POOL_EPISODES = 32
EPISODES_PER_WORKER = 2  # the paper's envs per worker: a per-worker buffer is written a cycle of them at a time
WARMUP = 10


def import_commit(commit: str, into: Path):
    """The package at ``commit``, importable as ``torchrl_cebp_before``."""
    archive = subprocess.run(["git", "archive", commit, "torchrl_cebp"], cwd=ROOT, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    (into / "torchrl_cebp").rename(into / "torchrl_cebp_before")
    for source in (into / "torchrl_cebp_before").rglob("*.py"):
        source.write_text(source.read_text().replace("torchrl_cebp", "torchrl_cebp_before"))
    sys.path.insert(0, str(into))
    import torchrl_cebp_before.replay

    return torchrl_cebp_before


Draw = Callable[[], object]


def build(package, cls_name: str, kwargs: dict, stored, pool, workers: int) -> tuple[Draw, Callable[[], object]]:
    """A filled buffer of ``package``'s: its draw, and a write of the next pool episodes (one per env of a cycle).

    With several workers ``kwargs`` are each worker's sampler's (a PER's capacity: its share, as training sizes it).
    """
    samplers = package.replay.samplers
    if workers == 1:
        sampler = getattr(samplers, cls_name)(**kwargs)
    else:
        sampler = samplers.PerWorkerSampler(*[getattr(samplers, cls_name)(**kwargs) for _ in range(workers)],
                                            episodes_per_worker=EPISODES_PER_WORKER)
    capacity = len(stored) * stored.u.shape[1]
    her = package.replay.HindsightRelabel(sparse_reward, future_p=FUTURE_P, strategy="future")
    rb = package.replay.make_replay_buffer(sampler, her, capacity=capacity, batch_size=BATCH_SIZE * workers)
    rb.extend(episodes_to_tensordict(stored))
    if hasattr(sampler, "refit"):
        sampler.refit(rb.storage)
    cycle = 1 if workers == 1 else workers * EPISODES_PER_WORKER
    fresh = itertools.cycle([episodes_to_tensordict(pool.slice(i, i + cycle)) for i in range(0, len(pool), cycle)])
    return rb.sample, lambda: rb.extend(next(fresh))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="the commit to compare this checkout with")
    parser.add_argument("--episodes", type=int, default=20000, help="stored 50-step episodes")
    parser.add_argument("--repeats", type=int, default=300, help="turns of each measurement")
    parser.add_argument("--samplers", nargs="+", default=None, help="a subset of the samplers (default: all)")
    parser.add_argument("--workers", type=int, default=1,
                        help="per-worker replay of this many workers (PerWorkerSampler, the paper's scale: 8): draws "
                             "of 256 per worker, writes of 2 episodes per worker; no TorchRL column")
    args = parser.parse_args()
    torch.set_num_threads(1)
    import torchrl_cebp.replay.samplers  # the package's samplers, as the other commit's
    from torchrl_cebp.training.builders import worker_share

    data = make_episodes(args.episodes + POOL_EPISODES, seed=0)
    stored, pool = data.slice(0, args.episodes), data.slice(args.episodes, len(data))
    capacity = args.episodes * stored.u.shape[1]
    if args.workers > 1:  # a PER's trees are sized by its worker's share
        capacity = worker_share(capacity, stored.u.shape[1], args.workers, EPISODES_PER_WORKER)
    arguments = our_samplers(capacity)
    names = args.samplers or list(arguments)
    unknown = sorted(set(names) - set(arguments))
    if unknown:
        parser.error(f"unknown samplers {unknown}; known: {sorted(arguments)}")
    print(f"median ms over {args.repeats} turns, {args.episodes} stored episodes, {args.workers} worker(s); "
          f"before = {args.before}, "
          "after = this checkout; write / TorchRL = this checkout's write over TorchRL's HERReplayBuffer's", flush=True)
    group = f"{'before':>8s} {'after':>8s} {'ratio':>6s}"
    written = "write one episode" if args.workers == 1 else f"write {args.workers * EPISODES_PER_WORKER} episodes"
    header = (f"{'':14s} {'draw':^24s}   {'draw after a write':^24s}   {written:^24s}   {'write':>9s}\n"
              f"{'sampler':14s} {group}   {group}   {group}   {'/ TorchRL':>9s}")
    print(header + "\n" + "-" * len(header.splitlines()[1]), flush=True)
    with tempfile.TemporaryDirectory() as scratch:
        before_package = import_commit(args.before, Path(scratch))
        for name in names:
            cls_name, kwargs = arguments[name]
            versions = {"old": build(before_package, cls_name, kwargs, stored, pool, args.workers),
                        "new": build(torchrl_cebp, cls_name, kwargs, stored, pool, args.workers)}
            torchrl_write = build_torchrl_her(stored, pool, WARMUP + 3 * args.repeats)[1] if args.workers == 1 else None
            measures = ("draw", "draw after write", "write")
            times: dict[str, list[float]] = {f"{v} {m}": [] for v in versions for m in measures}
            times["torchrl write"] = []
            for turn in range(WARMUP + args.repeats):
                for version, (draw, write) in in_turn_order(list(versions.items()), turn):
                    measured = {"draw": elapsed_ms(draw), "write": elapsed_ms(write)}
                    measured["draw after write"] = elapsed_ms(draw)
                    if turn >= WARMUP:
                        for measure, value in measured.items():
                            times[f"{version} {measure}"].append(value)
                torchrl_ms = elapsed_ms(torchrl_write) if torchrl_write is not None else math.nan
                if turn >= WARMUP:
                    times["torchrl write"].append(torchrl_ms)
            median = {key: statistics.median(values) for key, values in times.items()}
            columns = []
            for measure in measures:
                old, new = median[f"old {measure}"], median[f"new {measure}"]
                columns.append(f"{old:8.3f} {new:8.3f} {new / old:6.2f}")
            versus_torchrl = median["new write"] / median["torchrl write"]
            print(f"{name:14s} " + "   ".join(columns) + ("        -" if math.isnan(versus_torchrl) else
                                                            f"   {versus_torchrl:8.2f}x"), flush=True)
            del versions


if __name__ == "__main__":
    main()
