"""Contact Energy Based Prioritization (CEBP): the paper's equations, the released code's and the Initial commit's.

Three formulas of one idea (ORIGINAL_CODE.md §1), one class each, over a shared base that reads the
touch, the object's displacement and (for the code's forms) the gripper's workspace mask.
"""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.replay.samplers.base import (
    FLOAT32_EPS,
    EpisodePrioritySampler,
    episode_positions,
    require_key,
)
from torchrl_cebp.envs.layout import FETCH_OBSERVATION

# Gripper workspace boxes of the released code (min xyz, max xyz), per task.
RELEASED_WORKSPACES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "pick_place": ((1.05, 0.4, 0.419), (1.55, 1.1, float("inf"))),
    "push": ((1.05, 0.4, 0.4), (1.55, 1.11, float("inf"))),
    "slide": ((0.7, 0.3, 0.4), (1.95, 1.2, float("inf"))),
    # No released code for the Franka task: no workspace mask.
    "franka_pick_place": ((-float("inf"),) * 3, (float("inf"),) * 3),
}
# Paper defaults per task: (k, temperature); the released code's k per task.
PAPER_PARAMETERS = {
    "pick_place": (100.0, 0.01),
    "push": (100.0, 0.01),
    "slide": (100.0, 5.0),
    "franka_pick_place": (100.0, 0.01),  # the Sim2Real policy: PickAndPlace's values
}
RELEASED_K = {"pick_place": 0.1, "push": 0.1, "slide": 0.05, "franka_pick_place": 0.1}
# The code's forms use no IS correction until this many episodes are stored.
CODE_MIN_EPISODES_FOR_WEIGHTS = 256
INITIAL_BETA = 0.7


class _ContactEnergySampler(EpisodePrioritySampler):
    """What every CEBP form reads from an episode: touch, object displacement, and the gripper's workspace mask."""

    def __init__(
        self,
        task: str,
        touch_key: NestedKey,
        position_key: NestedKey,
        next_position_key: NestedKey,
        next_observation_key: NestedKey,
        generator: torch.Generator | None,
    ) -> None:
        super().__init__(generator)
        if task not in PAPER_PARAMETERS:
            raise ValueError(f"unknown task {task!r}; valid tasks: {sorted(PAPER_PARAMETERS)}")
        self.task = task
        self.touch_key = touch_key
        self.position_key = position_key
        self.next_position_key = next_position_key
        self.next_observation_key = next_observation_key
        low, high = RELEASED_WORKSPACES[task]
        self._workspace = (torch.tensor(low, dtype=torch.float64), torch.tensor(high, dtype=torch.float64))

    def _touch(self, episodes: TensorDictBase) -> torch.Tensor:
        """Left + right touch per step, ``[n, T]``."""
        return require_key(episodes, self.touch_key, (2,)).double().sum(-1)

    def _displacement(self, episodes: TensorDictBase) -> torch.Tensor:
        """The object's displacement over each step, ``[n, T, 3]``."""
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        return positions[:, 1:] - positions[:, :-1]

    def _in_workspace(self, episodes: TensorDictBase) -> torch.Tensor:
        """Whether the gripper is inside the task's workspace box after each step, ``[n, T]``."""
        observation = require_key(episodes, self.next_observation_key, (None,))
        gripper = observation[..., FETCH_OBSERVATION.gripper_position].double()
        low, high = self._workspace
        return ((gripper >= low) & (gripper <= high)).all(-1)

    @staticmethod
    def _code_weights(probabilities: torch.Tensor, n_episodes: int, beta: float) -> torch.Tensor:
        # The published code's rule: ones during warm-up, then (N p)^-beta over the batch maximum.
        if n_episodes < CODE_MIN_EPISODES_FOR_WEIGHTS:
            return torch.ones_like(probabilities)
        weights = (n_episodes * probabilities) ** (-beta)
        return weights / weights.max()


class CEBPSampler(_ContactEnergySampler):
    """CEBP as in the paper's equations: episodes drawn by their smoothed contact energy.

    Per step ``c(t) = sum_{i<=t} (f_l + f_r)(i) * ||d(i) - d(i-1)||`` (touch on both fingers
    times the object's displacement), smoothed to ``k / (1 + exp(-temperature * c(t)))``; the
    episode's priority is the sum over ``t``; IS weights ``(N p(e))^-beta`` over the batch maximum.
    For ``c >= 0`` the sigmoid lies in ``[k/2, k)``, so priorities differ at most 2x.

    Touch is only used here, to prioritise replay: the policy never sees it.

    Args:
        task: ``"pick_place"``, ``"push"``, ``"slide"`` or ``"franka_pick_place"``; selects the
            paper's defaults (k=100, T=0.01, or T=5 for slide; Franka takes PickAndPlace's).
        scale: the sigmoid's ``k`` (default per task).
        temperature: the sigmoid's ``T`` (default per task).
        beta: IS exponent (default 1.0).
        touch_key, position_key, next_position_key, next_observation_key: where
            touch ``[T, 2]``, the object position before each step and after it
            ``[T, 3]``, and the next observation (gripper position at
            ``FETCH_OBSERVATION.gripper_position``) live.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.samplers import CEBPSampler
        >>> T = 50
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(4, T, 3),
        ...     "next": {"achieved_goal": torch.rand(4, T, 3), "touch": torch.rand(4, T, 2),
        ...              "observation": torch.rand(4, T, 25)}}, [4, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2),
        ...                             sampler=CEBPSampler("push"), batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> batch["priority_weight"].shape
        torch.Size([8])
    """

    def __init__(
        self,
        task: str = "pick_place",
        *,
        scale: float | None = None,
        temperature: float | None = None,
        beta: float = 1.0,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey = ("next", "observation"),
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__(task, touch_key, position_key, next_position_key, next_observation_key, generator)
        default_scale, default_temperature = PAPER_PARAMETERS[task]
        for name, value in (("scale", scale), ("temperature", temperature)):
            if value is not None and not value > 0:
                raise ValueError(f"CEBPSampler {name}={value!r}: must be a positive number (or None for the task's default)")
        self.scale = default_scale if scale is None else float(scale)
        self.temperature = default_temperature if temperature is None else float(temperature)
        self.beta = float(beta)

    def episode_priority(self, episodes: TensorDictBase) -> torch.Tensor:
        distance = torch.linalg.vector_norm(self._displacement(episodes), dim=-1)
        energy = torch.cumsum(self._touch(episodes) * distance, dim=1)
        return (self.scale * torch.sigmoid(self.temperature * energy)).sum(1)

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        weights = (n_episodes * probabilities) ** (-self.beta)
        return weights / weights.max()

    def __repr__(self) -> str:
        return (
            f"CEBPSampler(task={self.task!r}, scale={self.scale}, temperature={self.temperature}, "
            f"beta={self.beta}, n_episodes={self.n_episodes})"
        )


class ReleasedCEBPSampler(_ContactEnergySampler):
    """CEBP as in the released code (HER_force's "ICRA submission" commit).

    A 3-vector ``E(t) = cumsum(displacement * (f_l + f_r))`` zeroed while the gripper is outside
    the task's workspace box, ``x(t) = sum(E(t)) * ||displacement||``, the centred sigmoid
    ``100 / (1 + exp(-k x)) - 50``, priority ``sum_t |s(t)| + eps``; IS weights ``(N p)^-1`` over the
    batch maximum, all ones while fewer than 256 episodes are stored.

    Args:
        task: selects ``k`` (0.1; 0.05 for slide) and the workspace box (none for the Franka task).
        k: the sigmoid's slope (default per task).
        touch_key, position_key, next_position_key, next_observation_key: as :class:`CEBPSampler`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.samplers import ReleasedCEBPSampler
        >>> T = 50
        >>> grip = torch.tensor([1.2, 0.6, 0.5] + [0.0] * 22)  # inside Push's workspace box
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(2, T, 3),
        ...     "next": {"achieved_goal": torch.rand(2, T, 3), "touch": torch.rand(2, T, 2),
        ...              "observation": torch.stack([grip.expand(T, 25), -grip.expand(T, 25)])}}, [2, T])
        >>> priority = ReleasedCEBPSampler("push").episode_priority(episodes)
        >>> bool(priority[0] > 1.0), bool(priority[1] < 1e-6)  # the second gripper never entered the box
        (True, True)
    """

    def __init__(
        self,
        task: str = "pick_place",
        *,
        k: float | None = None,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey = ("next", "observation"),
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__(task, touch_key, position_key, next_position_key, next_observation_key, generator)
        self.k = RELEASED_K[task] if k is None else float(k)

    def episode_priority(self, episodes: TensorDictBase) -> torch.Tensor:
        displacement = self._displacement(episodes)
        inside = self._in_workspace(episodes).unsqueeze(-1)
        energy = torch.cumsum(displacement * self._touch(episodes).unsqueeze(-1), dim=1) * inside
        x = energy.sum(-1) * torch.linalg.vector_norm(displacement, dim=-1)
        centred = 100.0 * torch.sigmoid(self.k * x) - 50.0
        return centred.abs().sum(1) + FLOAT32_EPS

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        return self._code_weights(probabilities, n_episodes, beta=1.0)

    def __repr__(self) -> str:
        return f"ReleasedCEBPSampler(task={self.task!r}, k={self.k}, n_episodes={self.n_episodes})"


class InitialCEBPSampler(_ContactEnergySampler):
    """CEBP as in the code's "Initial files" commit (the mocap Fetch): no sigmoid.

    Per step ``x(t) = (f_l + f_r)(t) * ||d(t) - d(t-1)||`` (touch zeroed while the gripper is outside
    the task's workspace box), priority ``sum_t |x(t)| + eps``; IS weights ``(N p)^-0.7`` over the
    batch maximum, all ones while fewer than 256 episodes are stored. Episodes without contact all
    share the priority ``eps``, so the few with contact dominate the draw.

    Args:
        task: selects the workspace box (none for the Franka task).
        beta: IS exponent (the commit's 0.7).
        touch_key, position_key, next_position_key, next_observation_key: as :class:`CEBPSampler`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.samplers import InitialCEBPSampler
        >>> T = 50
        >>> touch = torch.zeros(2, T, 2); touch[1] = 1.0  # only episode 1 touches
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(2, T, 3),
        ...     "next": {"achieved_goal": torch.rand(2, T, 3), "touch": touch,
        ...              "observation": torch.rand(2, T, 25) + torch.tensor([1.2, 0.6, 0.4] + [0.0] * 22)}}, [2, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2),
        ...                             sampler=InitialCEBPSampler("push"), batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> rb.sample()["index"][:, 0].tolist()
        [1, 1, 1, 1, 1, 1, 1, 1]
    """

    def __init__(
        self,
        task: str = "pick_place",
        *,
        beta: float = INITIAL_BETA,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey = ("next", "observation"),
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__(task, touch_key, position_key, next_position_key, next_observation_key, generator)
        self.beta = float(beta)

    def episode_priority(self, episodes: TensorDictBase) -> torch.Tensor:
        distance = torch.linalg.vector_norm(self._displacement(episodes), dim=-1)
        touch = self._touch(episodes) * self._in_workspace(episodes)
        return (touch * distance).abs().sum(1) + FLOAT32_EPS

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        return self._code_weights(probabilities, n_episodes, beta=self.beta)

    def __repr__(self) -> str:
        return f"InitialCEBPSampler(task={self.task!r}, beta={self.beta}, n_episodes={self.n_episodes})"
