"""Synthetic Fetch-like episodes and the peer replay buffers that ``sampling.py`` times ours against.

Peers: TorchRL 0.14's ``HERReplayBuffer``, Stable-Baselines3's ``HerReplayBuffer`` and a numpy
re-expression of the released CEBP sampler (erdiphd/HER_force, the authors' released code).
"""

from __future__ import annotations

import itertools
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

EPISODE_LENGTH = 50
BATCH_SIZE = 256
FUTURE_P = 0.8
DISTANCE_THRESHOLD = 0.05

# FetchPush-v4 observation layout (gymnasium-robotics ``_get_obs``).
GRIP_POS = slice(0, 3)
OBJECT_POS = slice(3, 6)
OBJECT_REL_POS = slice(6, 9)

# The released sampler's FetchPush workspace box for the gripper and its sigmoid slope.
PUSH_WORKSPACE_MIN = np.array([1.05, 0.4, 0.4])
PUSH_WORKSPACE_MAX = np.array([1.55, 1.11, np.inf])
RELEASED_PUSH_K = 0.1

Draw = Callable[[], object]
Write = Callable[[], None]


@dataclass(frozen=True)
class Episodes:
    """Episodes in the layout of the released buffer: T+1 observations / achieved goals, T of the rest."""

    obs: np.ndarray  # [n, T+1, 25]
    ag: np.ndarray  # [n, T+1, 3], the object position
    g: np.ndarray  # [n, T, 3]
    u: np.ndarray  # [n, T, 4]
    touch: np.ndarray  # [n, T, 2], left/right finger-pad touch at the step's end
    energy: np.ndarray  # [n, T, 3], the released rollout's running sum of displacement x touch
    is_success: np.ndarray  # [n, T]

    def __len__(self) -> int:
        return self.obs.shape[0]

    def slice(self, start: int, stop: int) -> Episodes:
        return Episodes(**{k: v[start:stop] for k, v in self.__dict__.items()})

    def reward(self) -> np.ndarray:
        """The stored (non-relabelled) sparse reward for each step, [n, T]."""
        return -(np.linalg.norm(self.ag[:, 1:] - self.g, axis=-1) > DISTANCE_THRESHOLD).astype(np.float32)


def elapsed_ms(fn: Callable[[], object]) -> float:
    """How long ``fn()`` takes, in milliseconds."""
    start = time.perf_counter()
    fn()
    return (time.perf_counter() - start) * 1e3


Timed = TypeVar("Timed")


def in_turn_order(timed: Sequence[Timed], turn: int) -> list[Timed]:
    """``timed`` in the order of this ``turn``: each goes first in every other turn, so that neither always finds the
    code warm that the other ran (a fixed order measured two identical versions 0.87-0.92x)."""
    return list(timed)[:: 1 if turn % 2 else -1]


def sparse_reward(achieved, goal):
    """HER's reward at ``DISTANCE_THRESHOLD``, as our relabelling computes it: 0 on reaching the goal, else -1."""
    import torch

    return -(torch.linalg.vector_norm(achieved - goal, dim=-1, keepdim=True) > DISTANCE_THRESHOLD).float()


def our_samplers(capacity: int) -> dict[str, tuple[str, dict]]:
    """Our samplers by name: the class in ``torchrl_cebp.replay.samplers`` and its arguments for FetchPush-shaped
    episodes (the env config's settings) in a storage of ``capacity`` transitions, by which PER's trees are sized."""
    from omegaconf import OmegaConf

    from torchrl_cebp.training.config import CONFIG_DIR

    push = OmegaConf.load(CONFIG_DIR / "env" / "push.yaml")
    workspace = tuple(map(tuple, push.gripper_workspace))
    return {
        "uniform": ("UniformEpisodeSampler", {}),
        "cebp_paper": ("CEBPSampler", {"temperature": push.cebp_temperature}),
        "cebp_released": ("ReleasedCEBPSampler", {"k": push.cebp_released_k, "workspace": workspace}),
        "cebp_initial": ("InitialCEBPSampler", {"workspace": workspace}),
        "cper": ("CPERSampler", {}),
        "ebp": ("EBPSampler", {}),
        "mep": ("MEPSampler", {}),
        "per": ("PERSampler", {"capacity": capacity}),
    }


def make_episodes(n: int, seed: int, T: int = EPISODE_LENGTH) -> Episodes:
    """Random but FetchPush-shaped episodes.

    Touch is sparse (about 1 step in 10 per finger) and the object only moves on touched steps, so
    the contact energy is zero for some episodes and spread over a wide range for the others: the
    prioritised samplers then see non-degenerate priorities.
    """
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, (n, T, 4)).astype(np.float32)

    grip = np.empty((n, T + 1, 3))
    grip[:, 0] = [1.34, 0.75, 0.53]
    grip[:, 0, :2] += rng.uniform(-0.01, 0.01, (n, 2))
    grip[:, 1:] = grip[:, :1] + np.cumsum(0.02 * u[..., :3], axis=1)
    grip = np.clip(grip, [1.0, 0.35, 0.41], [1.6, 1.15, 0.9])

    touch = rng.exponential(2.0, (n, T, 2)) * (rng.random((n, T, 2)) < 0.1)
    # A third of the episodes never touch, as early in training most do not.
    touch[rng.random(n) < 1 / 3] = 0.0
    pushed = touch.sum(-1, keepdims=True) > 0
    step = rng.normal(0.0, 0.01, (n, T, 3)) * [1.0, 1.0, 0.1] * pushed

    obj = np.empty((n, T + 1, 3))
    obj[:, 0, :2] = [1.34, 0.75] + rng.uniform(-0.15, 0.15, (n, 2))
    obj[:, 0, 2] = 0.425
    obj[:, 1:] = obj[:, :1] + np.cumsum(step, axis=1)

    obs = rng.normal(0.0, 0.05, (n, T + 1, 25))
    obs[..., GRIP_POS] = grip
    obs[..., OBJECT_POS] = obj
    obs[..., OBJECT_REL_POS] = obj - grip

    g = np.repeat(obj[:, :1] + np.append(rng.uniform(-0.15, 0.15, (n, 1, 2)), np.zeros((n, 1, 1)), -1), T, axis=1)
    energy = np.cumsum(np.diff(obj, axis=1) * touch.sum(-1, keepdims=True), axis=1)
    is_success = np.linalg.norm(obj[:, 1:] - g, axis=-1) <= DISTANCE_THRESHOLD
    return Episodes(
        obs=obs.astype(np.float32),
        ag=obj.astype(np.float32),
        g=g.astype(np.float32),
        u=u,
        touch=touch.astype(np.float32),
        energy=energy.astype(np.float32),
        is_success=is_success,
    )


def _fetch_push_env():
    import gymnasium as gym
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    return gym.make("FetchPush-v4")


def episodes_to_tensordict(episodes: Episodes):
    """The [n, T] TensorDict layout of a TorchRL collector's output for a touch-sensing Fetch env."""
    import torch
    from tensordict import TensorDict

    n, T = episodes.u.shape[:2]
    touch_before = np.concatenate([np.zeros_like(episodes.touch[:, :1]), episodes.touch[:, :-1]], axis=1)
    end = np.zeros((n, T, 1), dtype=bool)
    end[:, -1] = True
    success = torch.from_numpy(episodes.is_success[..., None].copy())
    return TensorDict(
        {
            "observation": torch.from_numpy(episodes.obs[:, :-1].copy()),
            "achieved_goal": torch.from_numpy(episodes.ag[:, :-1].copy()),
            "desired_goal": torch.from_numpy(episodes.g.copy()),
            "touch": torch.from_numpy(touch_before),
            "action": torch.from_numpy(episodes.u.copy()),
            "next": {
                "observation": torch.from_numpy(episodes.obs[:, 1:].copy()),
                "achieved_goal": torch.from_numpy(episodes.ag[:, 1:].copy()),
                "desired_goal": torch.from_numpy(episodes.g.copy()),
                "touch": torch.from_numpy(episodes.touch.copy()),
                "reward": torch.from_numpy(episodes.reward()[..., None]),
                "done": torch.from_numpy(end.copy()),
                "terminated": torch.zeros(n, T, 1, dtype=torch.bool),
                "truncated": torch.from_numpy(end.copy()),
                "is_success": success,
            },
        },
        batch_size=[n, T],
    )


def build_torchrl_her(stored: Episodes, pool: Episodes, n_writes: int) -> tuple[Draw, Write]:
    """TorchRL 0.14.1 ``HERReplayBuffer`` over a flat ``LazyTensorStorage`` of transitions.

    Its sample() raises once a full storage keeps being written (it compares tensor write cursors
    inside a tuple), so the storage gets room for every episode the harness will write and never
    wraps: the buffer grows by ``n_writes`` episodes while the writes are timed.
    """
    import torch
    from torchrl.data import HERReplayBuffer, LazyTensorStorage

    def reward_fn(td):
        distance = torch.linalg.vector_norm(td["next", "achieved_goal"] - td["desired_goal"], dim=-1, keepdim=True)
        return -(distance > DISTANCE_THRESHOLD).float()

    T = stored.u.shape[1]
    rb = HERReplayBuffer(
        reward_fn,
        her_ratio=FUTURE_P,
        strategy="future",
        # The next step's achieved goal: with the default key it relabels with the goal achieved
        # before step j, one step early; this gives t' in [t+1, T] as in baselines' HER.
        achieved_goal_key=("next", "achieved_goal"),
        storage=LazyTensorStorage((len(stored) + n_writes) * T),
        batch_size=BATCH_SIZE,
    )
    rb.extend(episodes_to_tensordict(stored).reshape(-1))
    fresh = itertools.cycle([episodes_to_tensordict(pool.slice(i, i + 1)).reshape(-1) for i in range(len(pool))])

    def write() -> None:
        rb.extend(next(fresh))

    return rb.sample, write


def require_stable_baselines3() -> None:
    """Exits, naming the install command, when the peer Stable-Baselines3 is missing (the ``bench`` extra)."""
    try:
        import stable_baselines3  # noqa: F401
    except ModuleNotFoundError:
        sys.exit("this benchmark runs Stable-Baselines3 beside ours: pip install -e '.[bench]' (or leave its sb3 methods out)")


def build_sb3_her(stored: Episodes, pool: Episodes, n_writes: int) -> tuple[Draw, Write]:
    """Stable-Baselines3 ``HerReplayBuffer`` filled transition by transition through add(), as its off-policy loop does."""
    from stable_baselines3 import HerReplayBuffer
    from stable_baselines3.common.vec_env import DummyVecEnv

    env = DummyVecEnv([_fetch_push_env])
    T = stored.u.shape[1]
    rb = HerReplayBuffer(
        len(stored) * T,
        env.observation_space,
        env.action_space,
        env=env,
        device="cpu",
        n_envs=1,
        n_sampled_goal=4,
        goal_selection_strategy="future",
    )

    def add_episodes(episodes: Episodes) -> None:
        obs, ag, g = episodes.obs.astype(np.float64), episodes.ag.astype(np.float64), episodes.g.astype(np.float64)
        reward = episodes.reward()
        for e in range(len(episodes)):
            for t in range(T):
                done = np.array([t == T - 1])
                rb.add(
                    {"observation": obs[e, t : t + 1], "achieved_goal": ag[e, t : t + 1], "desired_goal": g[e, t : t + 1]},
                    {
                        "observation": obs[e, t + 1 : t + 2],
                        "achieved_goal": ag[e, t + 1 : t + 2],
                        "desired_goal": g[e, t : t + 1],
                    },
                    episodes.u[e, t : t + 1],
                    reward[e, t : t + 1],
                    done,
                    [{"TimeLimit.truncated": bool(done[0]), "is_success": bool(episodes.is_success[e, t])}],
                )

    add_episodes(stored)
    fresh = itertools.cycle([pool.slice(i, i + 1) for i in range(len(pool))])

    def write() -> None:
        add_episodes(next(fresh))

    return lambda: rb.sample(BATCH_SIZE), write


class ReleasedCEBPBuffer:
    """The released CEBP replay (HER_force's baselines ``ReplayBuffer`` + contact-energy sampler), in numpy.

    Kept float64 and recomputing every stored episode's priority on each draw, as released: it is the
    reference for speed and for the released priority form, not code to train with.
    """

    def __init__(
        self,
        capacity_episodes: int,
        T: int,
        reward_fun: Callable[[np.ndarray, np.ndarray, dict], np.ndarray],
        future_p: float = FUTURE_P,
        workspace: tuple[np.ndarray, np.ndarray] = (PUSH_WORKSPACE_MIN, PUSH_WORKSPACE_MAX),
        k: float = RELEASED_PUSH_K,
        seed: int = 0,
    ) -> None:
        shapes = {
            "o": (T + 1, 25),
            "ag": (T + 1, 3),
            "g": (T, 3),
            "u": (T, 4),
            "info_is_success": (T, 1),
            "info_touch": (T, 2),
            "info_intrinsic_sum_energy": (T, 3),
        }
        self.buffers = {key: np.empty((capacity_episodes, *shape)) for key, shape in shapes.items()}
        self.size = capacity_episodes
        self.T = T
        self.current_size = 0
        self.reward_fun = reward_fun
        self.future_p = future_p
        self.workspace_min, self.workspace_max = workspace
        self.k = k
        self.rng = np.random.RandomState(seed)

    def store_episode(self, episodes: Episodes) -> None:
        idx = self._storage_idx(len(episodes))
        batch = {
            "o": episodes.obs,
            "ag": episodes.ag,
            "g": episodes.g,
            "u": episodes.u,
            "info_is_success": episodes.is_success[..., None],
            "info_touch": episodes.touch,
            "info_intrinsic_sum_energy": episodes.energy,
        }
        for key, value in batch.items():
            self.buffers[key][idx] = value

    def _storage_idx(self, inc: int) -> np.ndarray:
        # Consecutive until full, then random slots: the released buffer is not FIFO.
        if self.current_size + inc <= self.size:
            idx = np.arange(self.current_size, self.current_size + inc)
        elif self.current_size < self.size:
            overflow = inc - (self.size - self.current_size)
            idx = np.concatenate(
                [np.arange(self.current_size, self.size), self.rng.randint(0, self.current_size, overflow)]
            )
        else:
            idx = self.rng.randint(0, self.size, inc)
        self.current_size = min(self.size, self.current_size + inc)
        return idx

    def episode_probabilities(self, episodes: dict[str, np.ndarray]) -> np.ndarray:
        o = episodes["o"]
        grip = o[:, 1:, GRIP_POS]
        inside = np.all(grip > self.workspace_min, axis=-1) & np.all(grip < self.workspace_max, axis=-1)
        energy = (episodes["info_intrinsic_sum_energy"] * inside[..., None]).sum(-1)
        displacement = np.linalg.norm(o[:, 1:, OBJECT_POS] - o[:, :-1, OBJECT_POS], axis=-1)
        # Released form: centred sigmoid, so a step without contact energy contributes 0, not k/2.
        contact = 100.0 / (1.0 + np.exp(-self.k * energy * displacement)) - 50.0
        priority = np.abs(contact).sum(axis=1) + np.finfo(float).eps
        return priority / priority.sum()

    def sample(self, batch_size: int = BATCH_SIZE) -> tuple[dict[str, np.ndarray], np.ndarray]:
        episodes = {key: value[: self.current_size] for key, value in self.buffers.items()}
        episodes["o_2"] = episodes["o"][:, 1:]
        episodes["ag_2"] = episodes["ag"][:, 1:]
        n, T = self.current_size, self.T

        p = self.episode_probabilities(episodes)
        ep = self.rng.choice(n, size=batch_size, p=p)
        if n < batch_size:
            weights = np.ones(batch_size)
        else:
            # The released correction: beta 1, normalised by the mass of the distinct episodes drawn.
            weights = 1.0 / (T * n * p[ep] / p[np.unique(ep)].sum())
            weights /= weights.max()

        t = self.rng.randint(T, size=batch_size)
        her = np.where(self.rng.uniform(size=batch_size) < self.future_p)
        future_t = (t + 1 + (self.rng.uniform(size=batch_size) * (T - t)).astype(int))[her]
        transitions = {key: value[ep, t].copy() for key, value in episodes.items()}
        transitions["g"][her] = episodes["ag"][ep[her], future_t]
        info = {key.removeprefix("info_"): value for key, value in transitions.items() if key.startswith("info_")}
        transitions["r"] = self.reward_fun(transitions["ag_2"], transitions["g"], info)
        return transitions, weights


def build_released_cebp(stored: Episodes, pool: Episodes, n_writes: int) -> tuple[Draw, Write]:
    """The released sampler with FetchPush-v4's own compute_reward, as baselines' HER passes it."""
    env = _fetch_push_env()
    T = stored.u.shape[1]
    rb = ReleasedCEBPBuffer(len(stored), T, env.unwrapped.compute_reward)
    rb.store_episode(stored)
    fresh = itertools.cycle([pool.slice(i, i + 1) for i in range(len(pool))])

    def write() -> None:
        rb.store_episode(next(fresh))

    return rb.sample, write


PEERS: dict[str, Callable[[Episodes, Episodes, int], tuple[Draw, Write]]] = {
    "torchrl_her": build_torchrl_her,
    "sb3_her": build_sb3_her,
    "released_cebp": build_released_cebp,
}
