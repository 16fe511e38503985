"""The cost of per-worker replay in one draw: 8 workers' draws of 256 against one merged draw of 2048.

The paper-scale draw (``workers=8``, ``batch_size=256``) with HER relabelling, over a buffer of FetchPush-shaped
episodes written 16 at a time as the trainer writes them, for uniform HER, the Initial commit's CEBP and PER (whose
draw includes feeding the batch's TD errors back, ``rb.update_tensordict_priority``, as the trainer does). The two
layouts are timed in alternation, ``--rounds`` times ``--draws`` draws each, and the median of each is printed with
their ratio. A draw (with PER's priority update) is the only part of a training epoch whose code differs between the
layouts (2,000 of them per epoch): ``benchmarks/training.py --methods ours_merged:1 ours:1`` times the whole epoch.

    .venv/bin/python benchmarks/per_worker_draw.py --episodes 8000
"""
from __future__ import annotations

import argparse
import statistics
import time

import torch
from omegaconf import OmegaConf

from _peers import FUTURE_P, episodes_to_tensordict, make_episodes

WORKERS, EPISODES_PER_WORKER, BATCH_PER_WORKER = 8, 2, 256


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=8000, help="stored 50-step episodes (a multiple of 16)")
    parser.add_argument("--rounds", type=int, default=30, help="alternations of the two layouts")
    parser.add_argument("--draws", type=int, default=20, help="draws per layout per round")
    args = parser.parse_args()
    torch.set_num_threads(1)

    from torchrl_cebp.replay import HindsightRelabel, make_replay_buffer
    from torchrl_cebp.replay.samplers import InitialCEBPSampler, PERSampler, PerWorkerSampler, UniformEpisodeSampler
    from torchrl_cebp.training.config import CONFIG_DIR

    push = OmegaConf.load(CONFIG_DIR / "env" / "push.yaml")
    workspace = tuple(map(tuple, push.gripper_workspace))

    def reward_fn(ag: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        return -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()

    stored = episodes_to_tensordict(make_episodes(args.episodes, seed=0))
    capacity = 1_000_000
    samplers = {"her": lambda workers: UniformEpisodeSampler(),
                "cebp_initial": lambda workers: InitialCEBPSampler(workspace=workspace),
                "per": lambda workers: PERSampler(capacity // workers)}
    td_errors = torch.rand(WORKERS * BATCH_PER_WORKER, generator=torch.Generator().manual_seed(0))
    print(f"{args.episodes} episodes, a draw of {WORKERS} x {BATCH_PER_WORKER}; median ms per draw over "
          f"{args.rounds} rounds of {args.draws}")
    for name, make in samplers.items():
        buffers = {}
        for layout in ("merged", "per_worker"):
            sampler = make(1) if layout == "merged" else PerWorkerSampler(
                *[make(WORKERS) for _ in range(WORKERS)], episodes_per_worker=EPISODES_PER_WORKER)
            rb = make_replay_buffer(sampler, HindsightRelabel(reward_fn, future_p=FUTURE_P), capacity=capacity,
                                    batch_size=WORKERS * BATCH_PER_WORKER)
            for cycle in stored.split(WORKERS * EPISODES_PER_WORKER):
                rb.extend(cycle)
            buffers[layout] = rb
        times: dict[str, list[float]] = {layout: [] for layout in buffers}
        for _ in range(args.rounds):
            for layout, rb in buffers.items():
                tick = time.perf_counter()
                for _ in range(args.draws):
                    batch = rb.sample()
                    batch["td_error"] = td_errors  # fed back to PER only
                    rb.update_tensordict_priority(batch)
                times[layout].append((time.perf_counter() - tick) / args.draws * 1e3)
        merged, per_worker = (statistics.median(times[layout]) for layout in ("merged", "per_worker"))
        print(f"{name:13s} merged {merged:7.2f} ms   per-worker {per_worker:7.2f} ms   ratio {per_worker / merged:.2f}x   "
              f"(+{(per_worker - merged) * 2000 / 1e3:.1f} s over an epoch's 2,000 draws)")


if __name__ == "__main__":
    main()
