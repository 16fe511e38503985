"""TorchRL env driving touch-sensing Fetch gymnasium envs directly (no GymEnv wrapper or transforms)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
import torch
from gymnasium.utils import seeding
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_cebp.envs.franka import FRANKA_TASK, make_franka
from torchrl_cebp.envs.goal_spaces import TASKS
from torchrl_cebp.envs.joint_control import check_control
from torchrl_cebp.envs.touch_fetch import make_touch_fetch

ALL_TASKS: tuple[str, ...] = (*TASKS, FRANKA_TASK)


@dataclass(frozen=True)
class RobotOptions:
    """Which Fetch robot a task runs on; the defaults are gymnasium-robotics' mocap Fetch.

    The defaults are robot A, the Initial commit's robot, on which the paper's Fig. 2 was made;
    ``control="joint", touch_ignores_table=True`` (with ``touch_in_observation=True`` for PickAndPlace
    and Slide) is robot B, the released code's.

    Args:
        control (str, optional): ``"mocap"`` (4-D Cartesian action) or ``"joint"`` (CPER's joint position
            control, the released code's). Defaults to ``"mocap"``.
        touch_ignores_table (bool, optional): the pads never feel the table (CPER's sensor bodies).
            Defaults to ``False``.
        touch_in_observation (bool, optional): the observation gains the step's touch and its running
            episode sum. Defaults to ``False``.

    Raises:
        ValueError: ``control`` is not one of ``CONTROLS``.

    Example:
        >>> RobotOptions(control="joint", touch_ignores_table=True).label
        'joint-tableblind'
        >>> RobotOptions().label
        ''
    """

    control: str = "mocap"
    touch_ignores_table: bool = False
    touch_in_observation: bool = False

    def __post_init__(self) -> None:
        check_control(self.control)

    @property
    def label(self) -> str:
        """The robot's short name for folders, empty for the defaults, else e.g. ``joint-tableblind-touchobs``."""
        parts = [self.control] if self.control != "mocap" else []
        parts += ["tableblind"] if self.touch_ignores_table else []
        parts += ["touchobs"] if self.touch_in_observation else []
        return "-".join(parts)

    @classmethod
    def from_config(cls, env: Mapping) -> "RobotOptions":
        """The options an env config (``conf/env/*.yaml``) names; keys it lacks keep their defaults.

        Args:
            env (Mapping): the env config.

        Example:
            >>> RobotOptions.from_config({"task": "push", "control": "joint"}).label
            'joint'
        """
        return cls(**{key: env[key] for key in ("control", "touch_ignores_table", "touch_in_observation") if key in env})


def make_goal_env(task: str, goal_space: str = "standard", robot: RobotOptions = RobotOptions(),
                  grasped_start: float = 0.0, **kwargs):
    """The gymnasium touch-sensing goal env of any task, Fetch or Franka.

    Args:
        task (str): one of ``ALL_TASKS``.
        goal_space (str, optional): ``"standard"`` or ``"extended"`` (the Franka task: ``"standard"`` only).
            Defaults to ``"standard"``.
        robot (RobotOptions, optional): the Fetch robot (the Franka task: the defaults only).
            Defaults to ``RobotOptions()``.
        grasped_start (float, optional): the fraction of resets that begin with the cube grasped
            (:class:`~torchrl_cebp.envs.FrankaPickPlaceEnv`; the Franka task only). Defaults to ``0.0``.
        **kwargs: passed to gymnasium-robotics' env (``render_mode``, ``max_episode_steps``, ...).

    Returns:
        the gymnasium env, with its ``touch`` attribute.

    Raises:
        ValueError: an unknown task, or options the task does not have.

    Example:
        >>> make_goal_env("franka_pick_place").max_episode_steps
        100
    """
    if task == FRANKA_TASK:
        if robot != RobotOptions():
            raise ValueError(f"the Franka task has the mocap robot only (with its own touch pads); got {robot}")
        return make_franka(goal_space, grasped_start=grasped_start, **kwargs)
    if grasped_start:
        raise ValueError(f"grasped_start={grasped_start!r}: only {FRANKA_TASK} has grasped starts; use 0 for {task!r}")
    if task not in TASKS:
        raise ValueError(f"Unknown task {task!r}; valid tasks: {', '.join(ALL_TASKS)}")
    return make_touch_fetch(task, goal_space, **asdict(robot), **kwargs)

_OBS_KEYS = ("observation", "achieved_goal", "desired_goal")


class TouchFetchEnv(EnvBase):
    """A touch-sensing Fetch or Franka task as a TorchRL env (build it with :func:`make_env`).

    Root and ``"next"`` carry float32 ``observation`` [25] (27 with ``touch_in_observation``), ``achieved_goal`` [3], ``desired_goal`` [3],
    ``touch`` [2] (left, right; mean over the physics substeps) and bool ``is_success`` [1];
    ``"next"`` adds float32 ``reward`` [1] (0 on success else -1) and bool ``done``/``terminated``/``truncated`` [1]
    (truncated after ``max_episode_steps``, never terminated).

    With ``num_envs=n`` one env steps ``n`` MuJoCo simulations in a loop and has batch size ``[n]``:
    TorchRL's per-step overhead is then paid once per batch instead of once per simulation, which
    makes it several times cheaper than ``SerialEnv(n, ...)`` for these fast simulations.

    Args:
        task (str): one of ``ALL_TASKS``.
        goal_space (str, optional): ``"standard"`` or ``"extended"``. Defaults to ``"standard"``.
        device (torch.device or str, optional): where the env's tensors live. Defaults to ``"cpu"``.
        num_envs (int, optional): how many simulations one env steps; ``None`` gives an unbatched env.
            Defaults to ``None``.
        render_size (tuple of int, optional): ``(width, height)`` of the frames :meth:`render` returns;
            ``None`` renders nothing. Defaults to ``None``.
        robot (RobotOptions, optional): the Fetch robot. Defaults to ``RobotOptions()``.
        episode_steps (int, optional): replaces the task's episode length; ``None`` keeps its goal space's.
            Defaults to ``None``.
        grasped_start (float, optional): the fraction of episodes that begin with the cube grasped (the
            Franka task only). Defaults to ``0.0``.

    Example:
        >>> env = TouchFetchEnv("push", "extended")
        >>> env.rollout(3)["next", "touch"].shape
        torch.Size([3, 2])
        >>> TouchFetchEnv("push", num_envs=4).rollout(3)["next", "touch"].shape
        torch.Size([4, 3, 2])
        >>> TouchFetchEnv("push", "extended", robot=RobotOptions(control="joint")).action_spec.shape
        torch.Size([7])
    """

    def __init__(
        self,
        task: str,
        goal_space: str = "standard",
        device: torch.device | str = "cpu",
        num_envs: int | None = None,
        render_size: tuple[int, int] | None = None,
        robot: RobotOptions = RobotOptions(),
        episode_steps: int | None = None,
        grasped_start: float = 0.0,
    ) -> None:
        batch_size = torch.Size([] if num_envs is None else [num_envs])
        super().__init__(device=device, batch_size=batch_size)
        options = {} if render_size is None else {"render_mode": "rgb_array", "width": render_size[0], "height": render_size[1]}
        if episode_steps is not None:
            options["max_episode_steps"] = episode_steps
        self._sims = [make_goal_env(task, goal_space, robot, grasped_start, **options) for _ in range(max(1, batch_size.numel()))]
        first = self._sims[0]
        self.task = task
        self.goal_space = goal_space
        self.robot = robot
        self.max_episode_steps = first.max_episode_steps
        self.distance_threshold = first.distance_threshold
        self._steps = np.zeros(len(self._sims), dtype=np.int64)
        obs_dim = first.observation_space["observation"].shape[0]
        self._sizes = (obs_dim, 3, 3, 2)
        # Last observation of every simulation, one row each, so a partial reset can keep the others.
        self._rows = np.zeros((len(self._sims), sum(self._sizes)), dtype=np.float32)

        def vector(size: int) -> Unbounded:
            return Unbounded((*batch_size, size), dtype=torch.float32, device=self.device)

        def flag() -> Categorical:
            return Categorical(2, (*batch_size, 1), dtype=torch.bool, device=self.device)

        self.observation_spec = Composite(
            observation=vector(obs_dim),
            achieved_goal=vector(3),
            desired_goal=vector(3),
            touch=vector(2),
            is_success=flag(),
            shape=batch_size,
            device=self.device,
        )
        self.action_spec = Bounded(
            -1.0, 1.0, (*batch_size, first.action_space.shape[0]), dtype=torch.float32, device=self.device
        )
        self.reward_spec = vector(1)
        self.done_spec = Composite(
            {key: flag() for key in ("done", "terminated", "truncated")}, shape=batch_size, device=self.device
        )

    def compute_reward(self, achieved_goal: torch.Tensor, desired_goal: torch.Tensor) -> torch.Tensor:
        """Sparse reward for any leading batch dims: 0 within the distance threshold, else -1.

        Args:
            achieved_goal (torch.Tensor): ``[..., 3]`` object positions.
            desired_goal (torch.Tensor): ``[..., 3]`` targets.

        Returns:
            float32 ``[..., 1]``.

        Example:
            >>> env = TouchFetchEnv("push")
            >>> env.compute_reward(torch.zeros(5, 3), torch.full((5, 3), 0.01)).squeeze(-1)
            tensor([0., 0., 0., 0., 0.])
        """
        distance = torch.linalg.vector_norm(achieved_goal - desired_goal, dim=-1, keepdim=True)
        # Same sign convention as gymnasium-robotics (-1 beyond the threshold), without its -0.0.
        return (distance <= self.distance_threshold).to(torch.float32) - 1.0

    def render(self) -> np.ndarray:
        """RGB frames ``[*batch, H, W, 3]`` of the simulations (build the env with ``render_size``).

        Example:
            >>> env = TouchFetchEnv("push", render_size=(64, 48))
            >>> _ = env.reset()
            >>> env.render().shape
            (48, 64, 3)
        """
        if self._sims[0].render_mode != "rgb_array":
            raise RuntimeError("this env renders nothing: build it with render_size=(width, height)")
        frames = np.stack([sim.render() for sim in self._sims])
        return frames if self.batch_size else frames[0]

    def _store(self, i: int, obs: dict[str, np.ndarray]) -> None:
        row, start = self._rows[i], 0
        for value in (*(obs[key] for key in _OBS_KEYS), self._sims[i].touch):
            row[start : start + value.shape[0]] = value
            start += value.shape[0]

    def _read(self) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        # One tensor for the whole batch; the entries are views into it.
        flat = torch.from_numpy(self._rows.copy())
        if not self.batch_size:
            flat = flat.squeeze(0)
        out = dict(zip((*_OBS_KEYS, "touch"), flat.split(self._sizes, dim=-1)))
        # Reward from the float32 goals, so it matches compute_reward on stored transitions bit for bit.
        reward = self.compute_reward(out["achieved_goal"], out["desired_goal"])
        out["is_success"] = reward == 0
        return out, reward

    def _flags(self, values: np.ndarray) -> torch.Tensor:
        flags = torch.from_numpy(values).reshape(*self.batch_size, 1)
        return flags.clone() if flags.data_ptr() == 0 else flags

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        chosen = range(len(self._sims))
        if tensordict is not None and "_reset" in tensordict.keys() and self.batch_size:
            chosen = tensordict.get("_reset").reshape(-1).nonzero().squeeze(-1).tolist()
        for i in chosen:
            obs, _ = self._sims[i].reset()
            self._steps[i] = 0
            self._store(i, obs)
        out, _ = self._read()
        not_done = self._flags(np.zeros(len(self._sims), dtype=bool))
        out.update(done=not_done, terminated=not_done.clone(), truncated=not_done.clone())
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get("action").cpu().numpy().reshape(len(self._sims), -1)
        for i, (sim, action) in enumerate(zip(self._sims, actions)):
            obs, *_ = sim.step(action)
            self._store(i, obs)
        self._steps += 1
        out, reward = self._read()
        truncated = self._flags(self._steps >= self.max_episode_steps)
        out.update(
            reward=reward,
            done=truncated,
            terminated=torch.zeros_like(truncated),
            truncated=truncated.clone(),
        )
        return TensorDict(out, batch_size=self.batch_size, device=self.device)

    def _set_seed(self, seed: int | None) -> None:
        # Simulation i draws from seed + i: distinct streams, reproducible from one seed.
        for i, sim in enumerate(self._sims):
            sim.np_random, _ = seeding.np_random(None if seed is None else seed + i)


def make_env(
    task: str,
    goal_space: str = "standard",
    seed: int | None = None,
    device: torch.device | str = "cpu",
    num_envs: int | None = None,
    render_size: tuple[int, int] | None = None,
    control: str = "mocap",
    touch_ignores_table: bool = False,
    touch_in_observation: bool = False,
    episode_steps: int | None = None,
    grasped_start: float = 0.0,
) -> EnvBase:
    """The TorchRL env of ``task`` under ``goal_space``.

    Fetch tasks have the ``standard`` and ``extended`` goal spaces and both robots (:class:`RobotOptions`);
    the Franka task only ``standard`` and mocap. Picklable through ``functools.partial``, e.g. for
    ``ParallelEnv``.

    Args:
        task (str): ``"pick_place"``, ``"push"``, ``"slide"`` or ``"franka_pick_place"``.
        goal_space (str, optional): ``"standard"`` or ``"extended"``. Defaults to ``"standard"``.
        seed (int, optional): seeds simulation ``i`` with ``seed + i``; ``None`` leaves them unseeded.
            Defaults to ``None``.
        device (torch.device or str, optional): where the env's tensors live. Defaults to ``"cpu"``.
        num_envs (int, optional): ``n`` gives one env of batch size ``[n]`` stepping ``n`` simulations;
            ``None`` gives an unbatched env. Defaults to ``None``.
        render_size (tuple of int, optional): ``(width, height)``; enables ``env.render()``. Defaults to ``None``.
        control (str, optional): ``"mocap"`` or ``"joint"`` (:class:`RobotOptions`). Defaults to ``"mocap"``.
        touch_ignores_table (bool, optional): see :class:`RobotOptions`. Defaults to ``False``.
        touch_in_observation (bool, optional): see :class:`RobotOptions`. Defaults to ``False``.
        episode_steps (int, optional): replaces the task's episode length; ``None`` keeps its goal space's
            (the Franka's: 100). The Initial commit ran Slide with 70 steps on the standard goals;
            gymnasium's Slide has 50. Defaults to ``None``.
        grasped_start (float, optional): the fraction of episodes that begin with the cube grasped (the
            Franka task only; for training envs). Defaults to ``0.0``.

    Returns:
        a :class:`TouchFetchEnv`.

    Example:
        >>> env = make_env("pick_place", "extended", seed=0)
        >>> td = env.rollout(env.max_episode_steps)
        >>> bool(td["next", "truncated"][-1])
        True
        >>> make_env("pick_place", "extended", control="joint", touch_in_observation=True).action_spec.shape
        torch.Size([8])
    """
    robot = RobotOptions(control, touch_ignores_table, touch_in_observation)
    env = TouchFetchEnv(task, goal_space, device=device, num_envs=num_envs, render_size=render_size, robot=robot,
                        episode_steps=episode_steps, grasped_start=grasped_start)
    if seed is not None:
        env.set_seed(seed)
    return env


def make_env_from_config(env: Mapping, **kwargs) -> EnvBase:
    """The env an env config names (``conf/env/*.yaml``, or a checkpoint's saved one).

    The config's ``grasped_start`` is not applied: it is for training envs, which pass it in ``kwargs``.

    Args:
        env (Mapping): the env config: ``task`` and ``goal_space``, and optionally the :class:`RobotOptions`
            keys and ``episode_steps``.
        **kwargs: passed to :func:`make_env` (``seed``, ``num_envs``, ...).

    Example:
        >>> make_env_from_config({"task": "push", "goal_space": "extended", "control": "joint"}).action_spec.shape
        torch.Size([7])
    """
    return make_env(env["task"], env["goal_space"], **asdict(RobotOptions.from_config(env)),
                    episode_steps=env.get("episode_steps"), **kwargs)
