"""Before and after the replay rework: draws of the removed fork (commit 3ca970a) against this
checkout's stock buffer.

Both packages load into one process (the old one renamed ``torchrl_cebp_old``) and draw in
alternation, so that load drift on a shared machine hits both alike. Each line gives the median
time of a draw with 'future' HER relabelling from a full buffer.

    .venv/bin/python benchmarks/replay_rework.py --repeats 300
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from tensordict import TensorDict

BEFORE = "3ca970a"  # the last commit with EpisodeReplayBuffer (the fork of TorchRL's sample path)
T = 50
PUSH_WORKSPACE = ((1.05, 0.4, 0.4), (1.55, 1.11, float("inf")))


def import_before(commit: str, into: Path):
    """The package at ``commit``, importable as ``torchrl_cebp_old``."""
    root = Path(__file__).resolve().parents[1]
    archive = subprocess.run(["git", "archive", commit, "torchrl_cebp"], cwd=root, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    (into / "torchrl_cebp").rename(into / "torchrl_cebp_old")
    for source in (into / "torchrl_cebp_old").rglob("*.py"):
        source.write_text(source.read_text().replace("torchrl_cebp", "torchrl_cebp_old"))
    sys.path.insert(0, str(into))
    import torchrl_cebp_old.replay
    import torchrl_cebp_old.samplers

    return torchrl_cebp_old


def reward(achieved: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    return -(torch.linalg.vector_norm(achieved - goal, dim=-1, keepdim=True) > 0.05).float()


def episodes(n: int) -> TensorDict:
    g = torch.Generator().manual_seed(0)
    step = {key: torch.rand(n, T, width, generator=g)
            for key, width in (("observation", 25), ("achieved_goal", 3), ("desired_goal", 3), ("touch", 2))}
    return TensorDict({**step, "action": torch.rand(n, T, 4),
                       "next": {**step, "reward": torch.zeros(n, T, 1), "done": torch.zeros(n, T, 1, dtype=torch.bool)}},
                      [n, T])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    parser.add_argument("--episodes", type=int, nargs="+", default=[2000, 20000])
    parser.add_argument("--batch", type=int, nargs="+", default=[256, 2048])
    args = parser.parse_args()
    torch.set_num_threads(1)
    from torchrl_cebp import replay, samplers

    with tempfile.TemporaryDirectory() as scratch:
        old = import_before(BEFORE, Path(scratch))
        before = {"uniform": old.samplers.UniformEpisodeSampler, "cebp": lambda: old.samplers.CEBPSampler("push"),
                  "cebp_released": lambda: old.samplers.ReleasedCEBPSampler("push")}
        after = {"uniform": samplers.UniformEpisodeSampler, "cebp": samplers.CEBPSampler,
                 "cebp_released": lambda: samplers.ReleasedCEBPSampler(workspace=PUSH_WORKSPACE)}
        print(f"median ms per draw, {args.repeats} alternating draws each; fork = {BEFORE}, stock = this checkout")
        for batch in args.batch:
            for name in before:
                for n in args.episodes:
                    data = episodes(n)
                    fork = old.replay.make_replay_buffer(before[name](), reward_fn=reward, capacity=n * T, batch_size=batch)
                    stock = replay.make_replay_buffer(after[name](), replay.HindsightRelabel(reward), capacity=n * T,
                                                      batch_size=batch)
                    fork.extend(data)
                    stock.extend(data)
                    times: dict[str, list[float]] = {"fork": [], "stock": []}
                    for i in range(20 + args.repeats):
                        for label, rb in (("fork", fork), ("stock", stock)):
                            start = time.perf_counter()
                            rb.sample()
                            if i >= 20:
                                times[label].append(time.perf_counter() - start)
                    f, s = (statistics.median(times[k]) * 1e3 for k in ("fork", "stock"))
                    print(f"batch {batch:5d} {name:14s} {n:6d} episodes: fork {f:.3f}  stock {s:.3f}  stock/fork {s / f:.2f}",
                          flush=True)


if __name__ == "__main__":
    main()
