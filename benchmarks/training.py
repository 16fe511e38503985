"""Wall time of one DDPG+HER training epoch on FetchPush: our trainer against the peers, side by side in one run.

The same schedule for every method: ``cycles`` x (``2 x workers`` episodes of 50 steps, then 40
updates of ``256 x workers``), then ``10 x workers`` deterministic test episodes; 3 x 256 networks.
The methods run one after another, each with the torch threads given as ``NAME:THREADS``; by
default the peers get one thread (torch's default threads contend on a busy 2-core machine) and
two, and our trainer with ``overlap_collection=true`` gets two, which it shares with its env
process (a TorchRL collector) for the simulation: one while the env process collects, both once it
is done.

  * ours: ``torchrl_cebp.training.train`` (touch-sensing FetchPush, standard goals), overlap off and on,
    and overlapped with ``precision=bf16`` (bfloat16 matrix products in the updates); with ``--workers`` > 1
    it replays per worker (the default), ``ours_merged`` from one merged buffer (``replay.per_worker=false``),
    and the table adds the ratio of the two;
  * plain: a single-threaded PyTorch + numpy DDPG+HER loop written here on gymnasium's ``FetchPush-v4``
    (the floor a hand-written script reaches);
  * sb3: Stable-Baselines3 ``DDPG`` + ``HerReplayBuffer`` on ``FetchPush-v4`` (it moves its target
    networks after every gradient step, with tau 0.05, instead of once per cycle).

    .venv/bin/python benchmarks/training.py                       # a per-worker epoch (50 cycles)
    .venv/bin/python benchmarks/training.py --workers 8 --cycles 10   # paper scale, a fifth of an epoch
    .venv/bin/python benchmarks/training.py --workers 8 --cycles 10 --sampler cebp_initial \
        --methods ours_merged:1 ours:1 --repeats 3        # per-worker against merged replay, interleaved

With ``--repeats N`` every method runs N times, the methods interleaved in alternating order (A B, B A, ...),
and each reports its median: on shared cores a slow stretch, or a load that drifts, then lands on no method alone.
"""

from __future__ import annotations

import argparse
import copy
import csv
import tempfile
import time
from dataclasses import dataclass

import tensordict  # noqa: F401, I001  (before mujoco: tensordict's triton import crashes once OSMesa is loaded)
import torchrl_cebp.envs  # noqa: F401, I001  (before gymnasium-robotics: it keeps its Adroit notice off the terminal)
import gymnasium as gym
import gymnasium_robotics
import numpy as np
import torch
from _peers import require_stable_baselines3
from torch import nn

T = 50
HIDDEN = 256
UPDATES = 40
GAMMA = 1.0 - 1.0 / T


@dataclass
class Timing:
    epoch_s: float
    sim_s: float | None = None
    update_s: float | None = None


def run_ours(cycles: int, workers: int, overlap: bool, threads: int, precision: str = "fp32", sampler: str = "her",
             per_worker: bool = True) -> Timing:

    from torchrl_cebp.training import train
    from torchrl_cebp.training.config import compose_config

    cfg = compose_config(
        "env=push", "env.goal_space=standard", "epochs=1", f"cycles_per_epoch={cycles}", f"workers={workers}",
        f"overlap_collection={str(overlap).lower()}", f"threads={threads}", f"precision={precision}", "device=cpu",
        f"sampler={sampler}", f"replay.per_worker={str(per_worker).lower()}",
    )
    with tempfile.TemporaryDirectory() as run_dir:
        with open(train(cfg, run_dir), newline="") as f:
            row = next(csv.DictReader(f))
    return Timing(float(row["epoch_s"]), float(row["collect_s"]) + float(row["test_s"]), float(row["update_s"]))


def _mlp(n_in: int, n_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(n_in, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, HIDDEN), nn.ReLU(),
                         nn.Linear(HIDDEN, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, n_out))


class _Normaliser:
    def __init__(self, size: int) -> None:
        self.sum, self.sumsq, self.count = np.zeros(size), np.zeros(size), 0

    def update(self, x: np.ndarray) -> None:
        x = x.reshape(-1, self.sum.size)
        self.sum += x.sum(0)
        self.sumsq += np.square(x).sum(0)
        self.count += len(x)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        mean = self.sum / max(self.count, 1)
        std = np.sqrt(np.maximum(self.sumsq / max(self.count, 1) - mean**2, 1e-4))
        return np.clip((np.clip(x, -200, 200) - mean) / std, -5, 5).astype(np.float32)


def run_plain(cycles: int, workers: int, seed: int = 0) -> Timing:
    """Baselines' DDPG+HER written out with numpy episodes and PyTorch networks."""
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    n_envs, batch = 2 * workers, 256 * workers
    envs = [gym.make("FetchPush-v4") for _ in range(n_envs)]
    for i, env in enumerate(envs):
        env.reset(seed=seed + i)
    obs_dim, goal_dim, act_dim = 25, 3, 4
    actor, critic = nn.Sequential(_mlp(obs_dim + goal_dim, act_dim), nn.Tanh()), _mlp(obs_dim + goal_dim + act_dim, 1)
    actor_t, critic_t = copy.deepcopy(actor), copy.deepcopy(critic)
    actor_opt, critic_opt = torch.optim.Adam(actor.parameters(), 1e-3), torch.optim.Adam(critic.parameters(), 1e-3)
    o_norm, g_norm = _Normaliser(obs_dim), _Normaliser(goal_dim)
    store = {"o": [], "ag": [], "g": [], "u": []}  # per episode: T+1 obs/ag, T goals/actions

    def act(o: np.ndarray, g: np.ndarray, explore: bool) -> np.ndarray:
        with torch.no_grad():
            u = actor(torch.from_numpy(np.concatenate([o_norm(o), g_norm(g)], -1))).numpy()
        if explore:
            u = np.clip(u + 0.2 * rng.standard_normal(u.shape), -1, 1)
            random = rng.random(len(u)) < 0.3
            u[random] = rng.uniform(-1, 1, (random.sum(), act_dim))
        return u.astype(np.float32)

    def rollout(explore: bool) -> dict[str, np.ndarray]:
        obs = [env.reset()[0] for env in envs]
        ep = {"o": [], "ag": [], "g": [], "u": [], "success": None}
        for _ in range(T):
            o, ag, g = (np.stack([x[k] for x in obs]) for k in ("observation", "achieved_goal", "desired_goal"))
            u = act(o, g, explore)
            ep["o"].append(o), ep["ag"].append(ag), ep["g"].append(g), ep["u"].append(u)
            steps = [env.step(a) for env, a in zip(envs, u)]
            obs = [s[0] for s in steps]
            ep["success"] = np.array([s[4]["is_success"] for s in steps])
        ep["o"].append(np.stack([x["observation"] for x in obs]))
        ep["ag"].append(np.stack([x["achieved_goal"] for x in obs]))
        return {k: np.stack(v, 1) if k != "success" else v for k, v in ep.items()}

    def sample() -> list[torch.Tensor]:
        o, ag, g, u = (np.stack(store[k]) for k in ("o", "ag", "g", "u"))
        e, t = rng.integers(len(o), size=batch), rng.integers(T, size=batch)
        goal = g[e, t].copy()
        her = rng.random(batch) < 0.8
        future = t + 1 + (rng.random(batch) * (T - t)).astype(int)
        goal[her] = ag[e[her], future[her]]
        reward = -(np.linalg.norm(ag[e, t + 1] - goal, axis=-1) > 0.05).astype(np.float32)
        x = np.concatenate([o_norm(o[e, t]), g_norm(goal)], -1)
        x2 = np.concatenate([o_norm(o[e, t + 1]), g_norm(goal)], -1)
        return [torch.from_numpy(v) for v in (x, x2, u[e, t], reward[:, None])]

    def update() -> None:
        x, x2, u, r = sample()
        with torch.no_grad():
            y = (r + GAMMA * critic_t(torch.cat([x2, actor_t(x2)], -1))).clamp(-1 / (1 - GAMMA), 0)
        critic_loss = (critic(torch.cat([x, u], -1)) - y).pow(2).mean()
        critic_opt.zero_grad()
        critic_loss.backward()
        critic_opt.step()
        pi = actor(x)
        actor_loss = -critic(torch.cat([x, pi], -1)).mean() + pi.pow(2).mean()
        actor_opt.zero_grad()
        actor_loss.backward()
        actor_opt.step()

    sim_s = update_s = 0.0
    start = time.perf_counter()
    for _ in range(cycles):
        tick = time.perf_counter()
        ep = rollout(explore=True)
        for k in store:
            store[k].extend(ep[k])
        o_norm.update(ep["o"])
        g_norm.update(ep["g"])
        sim_s += time.perf_counter() - tick
        tick = time.perf_counter()
        for _ in range(UPDATES):
            update()
        with torch.no_grad():
            for net, target in ((actor, actor_t), (critic, critic_t)):
                for p, p_t in zip(net.parameters(), target.parameters()):
                    p_t.lerp_(p, 0.05)
        update_s += time.perf_counter() - tick
    tick = time.perf_counter()
    for _ in range(5):  # 10 x workers test episodes, 2 x workers at a time
        rollout(explore=False)
    sim_s += time.perf_counter() - tick
    return Timing(time.perf_counter() - start, sim_s, update_s)


def run_sb3(cycles: int, workers: int, seed: int = 0) -> Timing:
    from stable_baselines3 import DDPG, HerReplayBuffer
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.noise import NormalActionNoise

    n_envs = 2 * workers
    env = make_vec_env("FetchPush-v4", n_envs=n_envs, seed=seed)
    model = DDPG(
        "MultiInputPolicy", env, learning_rate=1e-3, buffer_size=1_000_000, learning_starts=0,
        batch_size=256 * workers, tau=0.05, gamma=GAMMA, train_freq=(T, "step"), gradient_steps=UPDATES,
        action_noise=NormalActionNoise(np.zeros(4), 0.2 * np.ones(4)),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [HIDDEN] * 3}, seed=seed, device="cpu",
    )
    update_s = 0.0
    sb3_train = model.train

    def timed_train(*args, **kwargs) -> None:
        nonlocal update_s
        tick = time.perf_counter()
        sb3_train(*args, **kwargs)
        update_s += time.perf_counter() - tick

    model.train = timed_train
    start = time.perf_counter()
    model.learn(total_timesteps=cycles * n_envs * T)
    test_env = make_vec_env("FetchPush-v4", n_envs=n_envs, seed=seed + 1)
    evaluate_policy(model, test_env, n_eval_episodes=10 * workers, deterministic=True)
    epoch_s = time.perf_counter() - start
    return Timing(epoch_s, epoch_s - update_s, update_s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cycles", type=int, default=50)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument(
        "--methods", nargs="+", default=["ours:1", "ours_overlap:2", "ours_overlap_bf16:2", "plain:1", "sb3:1", "sb3:2"],
        help="NAME[:THREADS] with NAME in ours, ours_merged, ours_overlap, ours_overlap_bf16, plain, sb3; THREADS (torch threads) defaults to --threads",
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads of a method given without :THREADS")
    parser.add_argument("--sampler", default="her", help="our trainer's sampler config (torchrl_cebp/conf/sampler/), e.g. cebp_initial")
    parser.add_argument("--repeats", type=int, default=1, help="runs of every method, interleaved; each reports its median")
    args = parser.parse_args()
    gym.register_envs(gymnasium_robotics)
    runners = {
        "ours": lambda threads: run_ours(args.cycles, args.workers, overlap=False, threads=threads, sampler=args.sampler),
        "ours_merged": lambda threads: run_ours(
            args.cycles, args.workers, overlap=False, threads=threads, sampler=args.sampler, per_worker=False
        ),
        "ours_overlap": lambda threads: run_ours(
            args.cycles, args.workers, overlap=True, threads=threads, sampler=args.sampler
        ),
        "ours_overlap_bf16": lambda threads: run_ours(
            args.cycles, args.workers, overlap=True, threads=threads, precision="bf16", sampler=args.sampler
        ),
        "plain": lambda threads: run_plain(args.cycles, args.workers),
        "sb3": lambda threads: run_sb3(args.cycles, args.workers),
    }
    if any(method.partition(":")[0] == "sb3" for method in args.methods):
        require_stable_baselines3()
    runs: dict[str, list[Timing]] = {}
    for repeat in range(args.repeats):
        # Every other repeat in reverse (A B B A ...): a load that drifts over the runs then favours no method.
        for method in args.methods if repeat % 2 == 0 else reversed(args.methods):
            name, _, threads = method.partition(":")
            if name not in runners:
                parser.error(f"unknown method {name!r}: choose from {', '.join(runners)}")
            n_threads = int(threads or args.threads)
            label = f"{name}:{n_threads}"
            torch.set_num_threads(n_threads)  # the peers run in this process; ours sets its own
            runs.setdefault(label, []).append(runners[name](n_threads))
            print(f"[{repeat + 1}/{args.repeats}] {label}: {runs[label][-1]}", flush=True)
    results = {label: _median(timings) for label, timings in runs.items()}

    def fmt(x: float | None) -> str:
        return "-" if x is None else f"{x:8.1f}"

    peers = [label for label in results if label.startswith(("sb3:", "plain:"))]
    print(f"\nFetchPush, {args.cycles} cycles x ({2 * args.workers} episodes + {UPDATES} updates of "
          f"{256 * args.workers}), {10 * args.workers} test episodes; seconds (sim includes the test episodes); "
          "NAME:THREADS = torch threads; 'vs P' = P's epoch time / this one's")
    width = max(len(label) for label in results)
    print(f"{'method':{width}s} {'epoch':>8s} {'sim':>8s} {'updates':>8s} " + " ".join(f"{'vs ' + p:>10s}" for p in peers))
    for label, t in results.items():
        ratios = " ".join(f"{results[p].epoch_s / t.epoch_s:9.2f}x" for p in peers)
        print(f"{label:{width}s} {fmt(t.epoch_s)} {fmt(t.sim_s)} {fmt(t.update_s)} {ratios}")
    for label in results:
        name, _, threads = label.partition(":")
        merged = results.get(f"ours_merged:{threads}")
        if name == "ours" and merged is not None:
            print(f"\nper-worker / merged replay ({args.sampler}, {args.workers} workers, {threads} thread(s), "
                  f"median of {args.repeats}): epoch {results[label].epoch_s / merged.epoch_s:.3f}x, "
                  f"updates {results[label].update_s / merged.update_s:.3f}x")


def _median(timings: list[Timing]) -> Timing:
    """The run of median epoch time (its sim and update times with it)."""
    return sorted(timings, key=lambda t: t.epoch_s)[(len(timings) - 1) // 2]


if __name__ == "__main__":
    main()
