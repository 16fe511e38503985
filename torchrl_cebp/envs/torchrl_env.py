"""TorchRL env driving a touch-sensing Fetch gymnasium env directly (no GymEnv wrapper or transforms)."""

from __future__ import annotations

import numpy as np
import torch
from gymnasium.utils import seeding
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_cebp.envs.touch_fetch import make_touch_fetch

_OBS_KEYS = ("observation", "achieved_goal", "desired_goal")


class TouchFetchEnv(EnvBase):
    """A touch-sensing Fetch task as a TorchRL env (build it with :func:`make_env`).

    Root and ``"next"`` carry float32 ``observation`` [25], ``achieved_goal`` [3], ``desired_goal`` [3],
    ``touch`` [2] (left, right; mean over the physics substeps) and bool ``is_success`` [1];
    ``"next"`` adds float32 ``reward`` [1] (0 on success else -1) and bool ``done``/``terminated``/``truncated`` [1]
    (truncated after ``max_episode_steps``, never terminated).

    Example:
        >>> env = TouchFetchEnv("push", "extended")
        >>> env.rollout(3)["next", "touch"].shape
        torch.Size([3, 2])
    """

    def __init__(self, task: str, goal_space: str = "standard", device: torch.device | str = "cpu") -> None:
        super().__init__(device=device, batch_size=torch.Size([]))
        self._env = make_touch_fetch(task, goal_space)
        self.task = task
        self.goal_space = goal_space
        self.max_episode_steps = self._env.max_episode_steps
        self.distance_threshold = self._env.distance_threshold
        self._steps = 0
        obs_dim = self._env.observation_space["observation"].shape[0]
        self._sizes = (obs_dim, 3, 3, 2)
        self.observation_spec = Composite(
            observation=Unbounded((obs_dim,), dtype=torch.float32, device=self.device),
            achieved_goal=Unbounded((3,), dtype=torch.float32, device=self.device),
            desired_goal=Unbounded((3,), dtype=torch.float32, device=self.device),
            touch=Unbounded((2,), dtype=torch.float32, device=self.device),
            is_success=Categorical(2, (1,), dtype=torch.bool, device=self.device),
            device=self.device,
        )
        self.action_spec = Bounded(-1.0, 1.0, (4,), dtype=torch.float32, device=self.device)
        self.reward_spec = Unbounded((1,), dtype=torch.float32, device=self.device)
        self.done_spec = Composite(
            {key: Categorical(2, (1,), dtype=torch.bool, device=self.device) for key in ("done", "terminated", "truncated")},
            device=self.device,
        )

    def compute_reward(self, achieved_goal: torch.Tensor, desired_goal: torch.Tensor) -> torch.Tensor:
        """Sparse reward for any leading batch dims: float32 [..., 1], 0 within the threshold else -1.

        Example:
            >>> env = TouchFetchEnv("push")
            >>> env.compute_reward(torch.zeros(5, 3), torch.full((5, 3), 0.01)).squeeze(-1)
            tensor([0., 0., 0., 0., 0.])
        """
        distance = torch.linalg.vector_norm(achieved_goal - desired_goal, dim=-1, keepdim=True)
        # Same sign convention as gymnasium-robotics (-1 beyond the threshold), without its -0.0.
        return (distance <= self.distance_threshold).to(torch.float32) - 1.0

    def _read(self, obs: dict[str, np.ndarray]) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        # One float32 conversion and one tensor per step; the entries are views into it.
        flat = torch.from_numpy(np.concatenate([*(obs[key] for key in _OBS_KEYS), self._env.touch]).astype(np.float32))
        out = dict(zip((*_OBS_KEYS, "touch"), flat.split(self._sizes)))
        # Reward from the float32 goals, so it matches compute_reward on stored transitions bit for bit.
        reward = self.compute_reward(out["achieved_goal"], out["desired_goal"])
        out["is_success"] = reward == 0
        return out, reward

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        obs, _ = self._env.reset()
        self._steps = 0
        out, _ = self._read(obs)
        not_done = torch.zeros(1, dtype=torch.bool)
        out.update(done=not_done, terminated=not_done.clone(), truncated=not_done.clone())
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        obs, *_ = self._env.step(tensordict.get("action").cpu().numpy())
        self._steps += 1
        out, reward = self._read(obs)
        truncated = torch.tensor([self._steps >= self.max_episode_steps])
        out.update(reward=reward, done=truncated, terminated=torch.zeros(1, dtype=torch.bool), truncated=truncated.clone())
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        self._env.np_random, _ = seeding.np_random(seed)


def make_env(task: str, goal_space: str = "standard", seed: int | None = None, device: torch.device | str = "cpu") -> EnvBase:
    """The TorchRL env of ``task`` (``pick_place``, ``push``, ``slide``) under ``goal_space`` (``standard``, ``extended``).

    Picklable through ``functools.partial``, e.g. for ``ParallelEnv``.

    Example:
        >>> env = make_env("pick_place", "extended", seed=0)
        >>> td = env.rollout(env.max_episode_steps)
        >>> bool(td["next", "truncated"][-1])
        True
    """
    env = TouchFetchEnv(task, goal_space, device=device)
    if seed is not None:
        env.set_seed(seed)
    return env
