"""Contact Energy Based Prioritization (CEBP): the paper's equations, the released code's and the Initial commit's.

Three formulas of one idea (the paper's equations, its released code, and that code's first commit), one class
each, over a shared base that reads the touch, the object's displacement and (for the code's forms) the gripper's
workspace mask.
"""
from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.replay.samplers.base import (
    FLOAT32_EPS,
    EpisodePrioritySampler,
    batch_normalised_weights,
    checked,
    episode_positions,
    require_key,
)
from torchrl_cebp.envs.layout import FETCH_OBSERVATION

# A gripper workspace box: (min xyz, max xyz). The per-task boxes are the env configs' ``gripper_workspace``.
Workspace = tuple[tuple[float, float, float], tuple[float, float, float]]
# The code's forms use no IS correction until this many episodes are stored.
CODE_MIN_EPISODES_FOR_WEIGHTS = 256
INITIAL_BETA = 0.7


class _ContactEnergySampler(EpisodePrioritySampler):
    """What every CEBP form reads from an episode: touch, object displacement, and the gripper's workspace mask."""

    def __init__(
        self,
        *,
        workspace: Workspace | None = None,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey | None = ("next", "observation"),
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(end_key)
        self.touch_key = touch_key
        self.position_key = position_key
        self.next_position_key = next_position_key
        self.next_observation_key = next_observation_key
        self.workspace = None if workspace is None else tuple(tuple(float(v) for v in corner) for corner in workspace)
        if self.workspace is not None and (len(self.workspace) != 2 or any(len(c) != 3 for c in self.workspace)):
            raise ValueError(f"workspace={workspace!r}: expected ((min x, y, z), (max x, y, z)) or None")

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        keys = {self.touch_key: (2,), self.position_key: (3,), self.next_position_key: (3,)}
        if self.next_observation_key is not None:  # the gripper's position, for the workspace mask
            keys[self.next_observation_key] = (None,)
        return keys

    def _touch(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Left + right touch per valid step (0 on padding), ``[n, T]``."""
        return require_key(episodes, self.touch_key, (2,)).double().sum(-1) * valid

    def _displacement(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """The object's displacement over each valid step (0 on padding), ``[n, T, 3]``."""
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        return (positions[:, 1:] - positions[:, :-1]) * valid.unsqueeze(-1)

    def _in_workspace(self, episodes: TensorDictBase) -> torch.Tensor:
        """Whether the gripper is inside the workspace box after each step (always, without a box), ``[n, T]``."""
        observation = require_key(episodes, self.next_observation_key, (None,))
        if self.workspace is None:
            return torch.ones(observation.shape[:2], dtype=torch.bool)
        gripper = observation[..., FETCH_OBSERVATION.gripper_position].double()
        low, high = (torch.tensor(corner, dtype=torch.float64) for corner in self.workspace)
        return ((gripper >= low) & (gripper <= high)).all(-1)

    @staticmethod
    def _code_weights(probabilities: torch.Tensor, n_episodes: int, beta: float) -> torch.Tensor:
        # The published code's rule: ones during warm-up, then the paper's weights.
        if n_episodes < CODE_MIN_EPISODES_FOR_WEIGHTS:
            return torch.ones_like(probabilities)
        return batch_normalised_weights(probabilities, n_episodes, beta)


class CEBPSampler(_ContactEnergySampler):
    """CEBP as in the paper's equations: episodes drawn by their smoothed contact energy.

    Per step ``c(t) = sum_{i<=t} (f_l + f_r)(i) * ||d(i) - d(i-1)||`` (touch on both fingers
    times the object's displacement), smoothed to ``k / (1 + exp(-temperature * c(t)))``; the
    episode's priority is the sum over ``t``; IS weights ``(N p(e))^-beta`` over the batch maximum.
    For ``c >= 0`` the sigmoid lies in ``[k/2, k)``, so priorities differ at most 2x.

    Touch is only used here, to prioritise replay: the policy never sees it.

    Args:
        scale (float, optional): the sigmoid's ``k``. Defaults to ``100.0``, the paper's.
        temperature (float, optional): the sigmoid's ``T``: the paper's 0.01, and 5 for Slide (the env config's
            ``cebp_temperature``). Defaults to ``0.01``.
        beta (float, optional): the IS exponent. Defaults to ``1.0``.
        touch_key (NestedKey, optional): the touch of both finger pads, ``[T, 2]``. Defaults to ``("next", "touch")``.
        position_key (NestedKey, optional): the object's position before each step, ``[T, 3]``.
            Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): the object's position after each step, ``[T, 3]``.
            Defaults to ``("next", "achieved_goal")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row does.
            Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import CEBPSampler
        >>> T = 50
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(4, T, 3),
        ...     "next": {"achieved_goal": torch.rand(4, T, 3), "touch": torch.rand(4, T, 2),
        ...              "observation": torch.rand(4, T, 25)}}, [4, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2),
        ...                             sampler=CEBPSampler(temperature=0.01), batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> batch["priority_weight"].shape
        torch.Size([8])
    """

    def __init__(
        self,
        *,
        scale: float = 100.0,
        temperature: float = 0.01,
        beta: float = 1.0,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(touch_key=touch_key, position_key=position_key, next_position_key=next_position_key,
                         next_observation_key=None, end_key=end_key)
        self.scale = checked("CEBPSampler", "scale", scale, exclusive=True)
        self.temperature = checked("CEBPSampler", "temperature", temperature, exclusive=True)
        self.beta = checked("CEBPSampler", "beta", beta)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        distance = torch.linalg.vector_norm(self._displacement(episodes, valid), dim=-1)
        energy = torch.cumsum(self._touch(episodes, valid) * distance, dim=1)
        return (self.scale * torch.sigmoid(self.temperature * energy) * valid).sum(1)

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        return batch_normalised_weights(probabilities, n_episodes, self.beta)

    def __repr__(self) -> str:
        return (
            f"CEBPSampler(scale={self.scale}, temperature={self.temperature}, "
            f"beta={self.beta}, n_episodes={self.n_episodes})"
        )


class ReleasedCEBPSampler(_ContactEnergySampler):
    """CEBP as in the released code (HER_force's "ICRA submission" commit).

    A 3-vector ``E(t) = cumsum(displacement * (f_l + f_r))`` zeroed while the gripper is outside
    the task's workspace box, ``x(t) = sum(E(t)) * ||displacement||``, the centred sigmoid
    ``100 / (1 + exp(-k x)) - 50``, priority ``sum_t |s(t)| + eps``; IS weights ``(N p)^-1`` over the
    batch maximum, all ones while fewer than 256 episodes are stored.

    Args:
        k (float, optional): the sigmoid's slope: the code's 0.1, and 0.05 for Slide (the env config's
            ``cebp_released_k``). Defaults to ``0.1``.
        workspace (tuple of two (x, y, z) tuples, optional): the gripper's box ``((min x, y, z), (max x, y, z))``
            (the env config's ``gripper_workspace``); touch outside it does not count. Defaults to ``None``, no mask.
        touch_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "touch")``.
        position_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "achieved_goal")``.
        next_observation_key (NestedKey, optional): the next observation, which holds the gripper's position at
            ``FETCH_OBSERVATION.gripper_position``. Defaults to ``("next", "observation")``.
        end_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay.samplers import ReleasedCEBPSampler
        >>> T = 50
        >>> grip = torch.tensor([1.2, 0.6, 0.5] + [0.0] * 22)  # inside Push's workspace box
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(2, T, 3),
        ...     "next": {"achieved_goal": torch.rand(2, T, 3), "touch": torch.rand(2, T, 2),
        ...              "observation": torch.stack([grip.expand(T, 25), -grip.expand(T, 25)])}}, [2, T])
        >>> push_box = ((1.05, 0.4, 0.4), (1.55, 1.11, float("inf")))  # conf/env/push.yaml's gripper_workspace
        >>> priority = ReleasedCEBPSampler(k=0.1, workspace=push_box).episode_priority(episodes, torch.ones(2, T, dtype=torch.bool))
        >>> bool(priority[0] > 1.0), bool(priority[1] < 1e-6)  # the second gripper never entered the box
        (True, True)
    """

    def __init__(self, *, k: float = 0.1, **keys: Any) -> None:
        super().__init__(**keys)
        self.k = checked("ReleasedCEBPSampler", "k", k, exclusive=True)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        displacement = self._displacement(episodes, valid)
        inside = self._in_workspace(episodes).unsqueeze(-1)
        energy = torch.cumsum(displacement * self._touch(episodes, valid).unsqueeze(-1), dim=1) * inside
        x = energy.sum(-1) * torch.linalg.vector_norm(displacement, dim=-1)
        centred = 100.0 * torch.sigmoid(self.k * x) - 50.0
        return centred.abs().sum(1) + FLOAT32_EPS

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        return self._code_weights(probabilities, n_episodes, beta=1.0)

    def __repr__(self) -> str:
        return f"ReleasedCEBPSampler(k={self.k}, workspace={self.workspace}, n_episodes={self.n_episodes})"


class InitialCEBPSampler(_ContactEnergySampler):
    """CEBP as in the code's "Initial files" commit (the mocap Fetch): no sigmoid.

    Per step ``x(t) = (f_l + f_r)(t) * ||d(t) - d(t-1)||`` (touch zeroed while the gripper is outside
    the task's workspace box), priority ``sum_t |x(t)| + eps``; IS weights ``(N p)^-0.7`` over the
    batch maximum, all ones while fewer than 256 episodes are stored. Episodes without contact all
    share the priority ``eps``, so the few with contact dominate the draw.

    Args:
        beta (float, optional): the IS exponent. Defaults to ``0.7``, the commit's.
        workspace (tuple of two (x, y, z) tuples, optional): as :class:`ReleasedCEBPSampler`. Defaults to ``None``.
        touch_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "touch")``.
        position_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "achieved_goal")``.
        next_observation_key (NestedKey, optional): as :class:`ReleasedCEBPSampler`.
            Defaults to ``("next", "observation")``.
        end_key (NestedKey, optional): as :class:`CEBPSampler`. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import InitialCEBPSampler
        >>> T = 50
        >>> touch = torch.zeros(2, T, 2); touch[1] = 1.0  # only episode 1 touches
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(2, T, 3),
        ...     "next": {"achieved_goal": torch.rand(2, T, 3), "touch": touch,
        ...              "observation": torch.rand(2, T, 25) + torch.tensor([1.2, 0.6, 0.4] + [0.0] * 22)}}, [2, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2),
        ...                             sampler=InitialCEBPSampler(workspace=((1.05, 0.4, 0.4), (1.55, 1.11, float("inf")))),
        ...                             batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> rb.sample()["index"][:, 0].tolist()
        [1, 1, 1, 1, 1, 1, 1, 1]
    """

    def __init__(self, *, beta: float = INITIAL_BETA, **keys: Any) -> None:
        super().__init__(**keys)
        self.beta = checked("InitialCEBPSampler", "beta", beta)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        distance = torch.linalg.vector_norm(self._displacement(episodes, valid), dim=-1)
        touch = self._touch(episodes, valid) * self._in_workspace(episodes)
        return (touch * distance).abs().sum(1) + FLOAT32_EPS

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        return self._code_weights(probabilities, n_episodes, beta=self.beta)

    def __repr__(self) -> str:
        return f"InitialCEBPSampler(beta={self.beta}, workspace={self.workspace}, n_episodes={self.n_episodes})"
