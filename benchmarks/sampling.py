"""Replay sampling speed of our samplers against the peers, side by side in one run.

For each stored-episode count it reports, per method, the median time to draw a batch of 256 with
'future' HER relabelling (future_p 0.8), to draw when one episode was written since the last draw
(what a training loop sees: samplers with caches pay for them here), and to write one 50-step episode. Each write
is also timed in turns with a write of TorchRL's own ``HERReplayBuffer``, each first in every other turn, so that a
shared machine's load drift falls on both alike; the last table divides by that. MEP is timed twice: as built, and
refitted once after the fill (``ours_mep_fitted``), whose writes rank the whole buffer as in training.

    .venv/bin/python benchmarks/sampling.py --episodes 2000 20000 --repeats 200
"""

from __future__ import annotations

import argparse
import gc
import itertools
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

import torch

from _peers import (
    BATCH_SIZE, EPISODE_LENGTH, FUTURE_P, PEERS, Draw, Episodes, Write, build_torchrl_her, elapsed_ms,
    episodes_to_tensordict, in_turn_order, make_episodes, our_samplers, require_stable_baselines3, sparse_reward,
)

# Episodes the write timings cycle through; fresh data, never the stored episodes again.
POOL_EPISODES = 32
WARMUP = 10

Builder = Callable[[Episodes, Episodes, int], tuple[Draw, Write]]


@dataclass(frozen=True)
class Timing:
    draw_ms: float
    draw_after_write_ms: float
    write_ms: float
    write_in_turns_ms: float
    torchrl_write_in_turns_ms: float

    @property
    def write_over_torchrl(self) -> float:
        """This method's write over TorchRL's, the two timed in the same turns."""
        return self.write_in_turns_ms / self.torchrl_write_in_turns_ms


def writes_needed(repeats: int) -> int:
    return WARMUP + 3 * repeats


def measure(draw: Draw, write: Write, repeats: int, torchrl_write: Write) -> Timing:
    """Medians over ``repeats``; makes exactly ``writes_needed(repeats)`` writes, and ``repeats`` of
    ``torchrl_write``."""
    for _ in range(WARMUP):
        draw()
        write()
    draws = [elapsed_ms(draw) for _ in range(repeats)]
    after_write = []
    for _ in range(repeats):
        write()
        after_write.append(elapsed_ms(draw))
    writes = [elapsed_ms(write) for _ in range(repeats)]
    in_turns: dict[Write, list[float]] = {write: [], torchrl_write: []}
    for turn in range(repeats):
        for timed in in_turn_order(list(in_turns), turn):
            in_turns[timed].append(elapsed_ms(timed))
    return Timing(statistics.median(draws), statistics.median(after_write), statistics.median(writes),
                  statistics.median(in_turns[write]), statistics.median(in_turns[torchrl_write]))


def _our_methods() -> dict[str, Builder]:
    """Our samplers behind ``make_replay_buffer``; empty (with a note) while the package lacks them."""
    try:
        from torchrl_cebp.replay import samplers
        from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
    except ImportError as err:
        print(f"note: our samplers are skipped, torchrl_cebp is not importable ({err})")
        return {}

    def builder(name: str, refit: bool = False) -> Builder:
        def build(stored: Episodes, pool: Episodes, n_writes: int) -> tuple[Draw, Write]:
            capacity = len(stored) * EPISODE_LENGTH
            cls_name, kwargs = our_samplers(capacity)[name]
            rb = make_replay_buffer(
                getattr(samplers, cls_name)(**kwargs),
                HindsightRelabel(sparse_reward, future_p=FUTURE_P, strategy="future"),
                capacity=capacity,
                batch_size=BATCH_SIZE,
            )
            rb.extend(episodes_to_tensordict(stored))
            if refit:
                rb.sampler.refit(rb.storage)
            fresh = itertools.cycle([episodes_to_tensordict(pool.slice(i, i + 1)) for i in range(len(pool))])

            def write() -> None:
                rb.extend(next(fresh))

            return rb.sample, write

        return build

    methods = {}
    for name, (cls_name, _) in our_samplers(0).items():  # (the capacity only sizes PER's trees)
        if hasattr(samplers, cls_name):
            methods[f"ours_{name}"] = builder(name)
            if name == "mep":
                methods["ours_mep_fitted"] = builder(name, refit=True)
        else:
            print(f"note: ours_{name} is skipped, torchrl_cebp.replay.samplers has no {cls_name}")
    return methods


def _turns_table(title: str, results: dict[str, Timing]) -> str:
    """Each method's write beside the TorchRL write timed in the same turns, and their ratio."""
    header = f"{'method':<20} {'median ms':>10} {'TorchRL ms':>11} {'/ TorchRL':>10}"
    lines = [title, header, "-" * len(header)]
    for name, timing in results.items():
        lines.append(f"{name:<20} {timing.write_in_turns_ms:>10.3f} {timing.torchrl_write_in_turns_ms:>11.3f} "
                     f"{timing.write_over_torchrl:>9.3g}x")
    return "\n".join(lines)


def _table(title: str, results: dict[str, Timing], field: str) -> str:
    peers = [p for p in PEERS if p in results]
    header = f"{'method':<20} {'median ms':>10}" + "".join(f" {'/ ' + p:>16}" for p in peers)
    lines = [title, header, "-" * len(header)]
    for name, timing in results.items():
        value = getattr(timing, field)
        ratios = "".join(f" {value / getattr(results[p], field):>15.3g}x" for p in peers)
        lines.append(f"{name:<20} {value:>10.3f}{ratios}")
    return "\n".join(lines)


def run(n_episodes: int, repeats: int, methods: dict[str, Builder]) -> dict[str, Timing]:
    data = make_episodes(n_episodes + POOL_EPISODES, seed=0)
    stored, pool = data.slice(0, n_episodes), data.slice(n_episodes, len(data))
    # A second TorchRL buffer of its own, written in turns with each method's writes.
    _, torchrl_write = build_torchrl_her(stored, pool, WARMUP + repeats * len(methods))
    results = {}
    for name, build in methods.items():
        start = time.perf_counter()
        draw, write = build(stored, pool, writes_needed(repeats))
        built_s = time.perf_counter() - start
        results[name] = measure(draw, write, repeats, torchrl_write)
        print(f"  {name}: built in {built_s:.1f} s, {results[name]}", flush=True)
        # Drop the buffer before the next method so its memory and GC load do not bias the next timing.
        del draw, write
        gc.collect()
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, nargs="+", default=[2000, 20000], help="stored 50-step episodes")
    parser.add_argument("--repeats", type=int, default=200, help="timed draws (and writes) per median")
    parser.add_argument("--peers-only", action="store_true", help="skip our samplers")
    parser.add_argument("--peers", nargs="+", choices=list(PEERS), default=list(PEERS),
                        help="the peers to time beside ours (sb3_her needs the bench extra)")
    args = parser.parse_args()

    # Shared 2-core machines: more threads only add contention, and the peers' reference runs used 1.
    torch.set_num_threads(1)
    if "sb3_her" in args.peers:
        require_stable_baselines3()
    methods: dict[str, Builder] = {name: PEERS[name] for name in args.peers}
    if not args.peers_only:
        methods.update(_our_methods())

    print(f"torch {torch.__version__}, batch {BATCH_SIZE}, future_p {FUTURE_P}, {args.repeats} repeats")
    print("ratio columns: this method's median time / the peer's (below 1: faster than that peer)")
    print("torchrl_her's storage is sized to never wrap (its sample() fails after a wrap): it grows by")
    print(f"{writes_needed(args.repeats)} episodes while the write timings run; every other buffer stays full.")
    for n in args.episodes:
        print(f"\n== {n} stored episodes ({n * EPISODE_LENGTH:,} transitions) ==", flush=True)
        results = run(n, args.repeats, methods)
        for title, field in (
            ("draw a batch", "draw_ms"),
            ("draw a batch, one episode written since the last draw", "draw_after_write_ms"),
            ("write one episode", "write_ms"),
        ):
            print("\n" + _table(f"{title} ({n} episodes)", results, field))
        turns_title = f"write one episode, in turns with a write of TorchRL's HERReplayBuffer ({n} episodes)"
        print("\n" + _turns_table(turns_title, results))


if __name__ == "__main__":
    main()
