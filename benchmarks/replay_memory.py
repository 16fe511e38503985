"""Resident memory of the trainer's replay at the paper's scale: each of the 8 workers' own 1e6 transitions
(``replay.capacity_per=worker``, 8e6 in all) against the 1e6 they share (``total``).

For each layout and epoch count, a fresh process fills the replay with the episodes of that many epochs
(16 real FetchPush episodes a cycle, 50 cycles an epoch, written again and again) and reports what the replay
added to its resident memory, and the size of the replay's checkpoint state. A second fresh process restores
that state into a new replay and draws once; it reports what that added, at the end and at its peak.

    .venv/bin/python benchmarks/replay_memory.py --epochs 1 25 50
"""
from __future__ import annotations

import argparse
import gc
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import torch

import torchrl_cebp.training.config  # noqa: F401  (registers the config's resolvers)
from torchrl_cebp.training.config import compose_config
from torchrl_cebp.training.builders import (
    TaskDims, episodes_per_cycle, make_agent, make_env, make_replay, make_sampler, make_training_collector,
    replay_capacity,
)

REPO = Path(__file__).resolve().parents[1]
MIB = 2**20


def resident_mib() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / MIB


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kilobytes on Linux


def config(sampler: str, capacity_per: str):
    return compose_config("preset=paper", "env=push", f"sampler={sampler}", f"replay.capacity_per={capacity_per}")


def fill(sampler: str, capacity_per: str, epochs: int, state_path: Path) -> None:
    cfg = config(sampler, capacity_per)
    env = make_env(cfg, episodes_per_cycle(cfg))
    agent = make_agent(cfg, TaskDims.of(env))
    batches = make_training_collector(cfg, agent, TaskDims.of(env))
    batches.request(0)
    episodes = batches.result()
    gc.collect()
    before = resident_mib()
    replay, _ = make_replay(cfg, make_sampler(cfg), env)
    for _ in range(epochs * cfg.cycles_per_epoch):
        replay.extend(episodes)
    replay.sample()
    added = resident_mib() - before
    torch.save(replay.state_dict(), state_path)
    print(f"RESULT {replay_capacity(cfg):,} {len(replay):,} {added:.0f} {state_path.stat().st_size / MIB:.0f}")


def restore(sampler: str, capacity_per: str, state_path: Path) -> None:
    cfg = config(sampler, capacity_per)
    env = make_env(cfg)
    replay, _ = make_replay(cfg, make_sampler(cfg), env)
    gc.collect()
    before = resident_mib()
    replay.load_state_dict(torch.load(state_path, weights_only=True))  # the peak includes the loaded state
    replay.sample()
    gc.collect()
    print(f"RESULT {resident_mib() - before:.0f} {peak_mib() - before:.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--epochs", type=int, nargs="+", default=[1, 25, 50], help="epochs of episodes to store")
    parser.add_argument("--sampler", default="cebp_initial", help="the sampler config (torchrl_cebp/conf/sampler/)")
    parser.add_argument("--layouts", nargs="+", default=["worker", "total"], choices=["worker", "total"],
                        help="replay.capacity_per values to compare")
    parser.add_argument("--child", nargs=4, metavar=("MODE", "LAYOUT", "EPOCHS", "STATE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        mode, layout, epochs, state = args.child
        if mode == "fill":
            fill(args.sampler, layout, int(epochs), Path(state))
        else:
            restore(args.sampler, layout, Path(state))
        return
    print(f"FetchPush, preset=paper (8 workers, 16 episodes a cycle), sampler={args.sampler}; MiB resident added "
          "by the replay; each figure from a fresh process")
    print(f"{'layout':>6} {'epochs':>6} {'capacity':>12} {'stored':>12} {'filled':>10} {'state':>10} "
          f"{'restored':>10} {'peak':>10}")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "osmesa")}
    with tempfile.TemporaryDirectory() as scratch:
        for epochs in args.epochs:
            for layout in args.layouts:
                state = str(Path(scratch) / "replay.pt")
                figures = []
                for mode in ("fill", "restore"):
                    out = subprocess.run([sys.executable, __file__, "--sampler", args.sampler, "--child", mode, layout,
                                          str(epochs), state], env=env, check=True, capture_output=True, text=True)
                    figures += next(line for line in out.stdout.splitlines() if line.startswith("RESULT")).split()[1:]
                print(f"{layout:>6} {epochs:>6} " + " ".join(f"{figure:>12}" if i < 2 else f"{figure:>10}"
                                                              for i, figure in enumerate(figures)), flush=True)


if __name__ == "__main__":
    main()
