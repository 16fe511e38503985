"""Contact Energy Based Prioritization (CEBP): the paper's equations, its released code and that code's first commit."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.envs.layout import FETCH_OBSERVATION
from torchrl_cebp.replay.samplers.base import (FLOAT32_EPS, EpisodePrioritySampler, batch_normalised_weights, checked,
                                               episode_positions, require_key)

# A gripper workspace box: (min xyz, max xyz). The per-task boxes are the env configs' ``gripper_workspace``.
Workspace = tuple[tuple[float, float, float], tuple[float, float, float]]
GRIPPER_POSITION = FETCH_OBSERVATION.gripper_position  # read once: the layout's attribute lookup costs a microsecond


class _ContactEnergySampler(EpisodePrioritySampler):
    """What every CEBP form reads from an episode: touch, object displacement, and the gripper's workspace mask."""

    # The code's forms use no IS correction until this many episodes are stored; the paper's from the start.
    _warmup_episodes = 256

    def __init__(
        self, *, workspace: Workspace | None = None, touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal", next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey | None = ("next", "observation"), end_key: NestedKey = ("next", "done"),
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
        """The entries read, with their per-step shapes: both pads' touch ``(2,)``, the object's position before and
        after each step ``(3,)``, and the next observation (any width), unless ``next_observation_key`` is ``None``
        (:class:`CEBPSampler`, which masks no workspace)."""
        keys = {self.touch_key: (2,), self.position_key: (3,), self.next_position_key: (3,)}
        if self.next_observation_key is not None:  # the gripper's position, for the workspace mask
            keys[self.next_observation_key] = (None,)
        return keys

    def _touch(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Left + right touch per valid step (0 on padding, whatever it holds: NaN * 0 is NaN), ``[n, T]``."""
        return require_key(episodes, self.touch_key, (2,)).sum(-1, dtype=torch.float64).where(valid, 0.0)

    def _displacement(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """The object's displacement over each valid step (0 on padding), ``[n, T, 3]``."""
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        return positions.diff(dim=1).where(valid.unsqueeze(-1), 0.0)

    def _in_workspace(self, episodes: TensorDictBase) -> torch.Tensor:
        """Whether the gripper is inside the workspace box after each step (always, without a box), ``[n, T]``."""
        observation = require_key(episodes, self.next_observation_key, (None,))
        if self.workspace is None:
            return torch.ones(observation.shape[:2], dtype=torch.bool)
        low, high = _corners(self.workspace)
        gripper = observation[..., GRIPPER_POSITION].double()  # once: a comparison of mixed dtypes converts each time
        return ((gripper >= low) & (gripper <= high)).all(-1)

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        """IS weights ``(N p)^-beta`` of the drawn episodes, divided by the batch's largest.

        As in the authors' code, all ones while fewer than 256 episodes are stored; the paper's form
        (:class:`CEBPSampler`) weighs from the first episode.

        Args:
            probabilities (torch.Tensor): each drawn episode's probability ``p``.
            n_episodes (int): the number of stored episodes ``N``.
        """
        if n_episodes < self._warmup_episodes:
            return torch.ones_like(probabilities)
        return batch_normalised_weights(probabilities, n_episodes, self.beta)


@lru_cache(maxsize=16)
def _corners(workspace: Workspace) -> tuple[torch.Tensor, ...]:
    """A box's two corners as float64 tensors, made once per box rather than on every write."""
    return tuple(torch.tensor(corner, dtype=torch.float64) for corner in workspace)


class CEBPSampler(_ContactEnergySampler):
    """CEBP as in the paper's equations: episodes drawn by the sum over steps of a sigmoid of their contact energy.

    The formulas of the three CEBP forms are on the :doc:`samplers page </samplers>`. Only replay reads the touch,
    never the policy.

    Args:
        scale (float, optional): the sigmoid's ``k``. Defaults to ``100.0``, the paper's.
        temperature (float, optional): the sigmoid's ``T`` (the env's ``cebp_temperature``). Defaults to ``0.01``.
        beta (float, optional): the IS exponent. Defaults to ``1.0``.
        touch_key (NestedKey, optional): both finger pads' touch, ``[T, 2]``. Defaults to ``("next", "touch")``.
        position_key (NestedKey, optional): the object's position before a step. Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): its position after a step. Defaults to ``("next", "achieved_goal")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import CEBPSampler
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * 50, ndim=2), sampler=CEBPSampler(),
        ...                             batch_size=8, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"achieved_goal": torch.zeros(4, 50, 3), "next": {
        ...     "achieved_goal": torch.rand(4, 50, 3), "touch": torch.rand(4, 50, 2)}}, [4, 50]))
        >>> rb.sample()["priority_weight"].shape
        torch.Size([8])
    """

    _warmup_episodes = 0

    def __init__(
        self, *, scale: float = 100.0, temperature: float = 0.01, beta: float = 1.0,
        touch_key: NestedKey = ("next", "touch"), position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"), end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(touch_key=touch_key, position_key=position_key, next_position_key=next_position_key,
                         next_observation_key=None, end_key=end_key)
        self.scale = checked("CEBPSampler", "scale", scale, exclusive=True)
        self.temperature = checked("CEBPSampler", "temperature", temperature, exclusive=True)
        self.beta = checked("CEBPSampler", "beta", beta)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Each episode's sum over its valid steps of ``scale * sigmoid(temperature * c(t))``, where the contact
        energy ``c(t)`` sums, up to step ``t``, both pads' touch times the length of the object's displacement.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes holding the :meth:`episode_keys` entries.
            valid (torch.Tensor): bool ``[n, T]``, the steps before each episode's end; padding adds nothing.

        Returns:
            float64 ``[n]`` priorities; with non-negative touch each valid step adds between ``scale / 2`` and
            ``scale``.
        """
        distance = torch.linalg.vector_norm(self._displacement(episodes, valid), dim=-1)
        energy = torch.cumsum(self._touch(episodes, valid) * distance, dim=1)
        return (self.scale * torch.sigmoid(self.temperature * energy) * valid).sum(1)

    def __repr__(self) -> str:
        return (f"CEBPSampler(scale={self.scale}, temperature={self.temperature}, beta={self.beta}, "
                f"n_episodes={self.n_episodes})")


class ReleasedCEBPSampler(_ContactEnergySampler):
    """CEBP as in the released code (HER_force's "ICRA submission" commit): a centred sigmoid of the contact energy
    in the gripper's workspace box; IS weights of exponent 1, all ones below 256 stored episodes.

    Args:
        k (float, optional): the sigmoid's slope (the env's ``cebp_released_k``). Defaults to ``0.1``, the code's.
        workspace (tuple of two (x, y, z) tuples, optional): the gripper's box ``((min x, y, z), (max x, y, z))``
            (the env config's ``gripper_workspace``); touch outside it does not count. Defaults to ``None``, no box.
        touch_key, position_key, next_position_key, end_key (NestedKey, optional): as :class:`CEBPSampler`.
        next_observation_key (NestedKey, optional): the next observation, which holds the gripper's position at
            ``FETCH_OBSERVATION.gripper_position``. Defaults to ``("next", "observation")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay.samplers import ReleasedCEBPSampler
        >>> grip = torch.tensor([1.2, 0.6, 0.5] + [0.0] * 22)  # inside the box below
        >>> episodes = TensorDict({"achieved_goal": torch.zeros(2, 50, 3), "next": {
        ...     "achieved_goal": torch.rand(2, 50, 3), "touch": torch.rand(2, 50, 2),
        ...     "observation": torch.stack([grip, -grip]).unsqueeze(1).expand(2, 50, 25)}}, [2, 50])
        >>> sampler = ReleasedCEBPSampler(workspace=((1.05, 0.4, 0.4), (1.55, 1.11, float("inf"))))  # Push's
        >>> priority = sampler.episode_priority(episodes, torch.ones(2, 50, dtype=torch.bool))
        >>> bool(priority[0] > 1.0), bool(priority[1] < 1e-6)  # the second gripper never entered the box
        (True, True)
    """

    beta = 1.0  #: The IS exponent, fixed at the released code's 1.

    def __init__(self, *, k: float = 0.1, **keys: Any) -> None:
        super().__init__(**keys)
        self.k = checked("ReleasedCEBPSampler", "k", k, exclusive=True)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Each episode's sum over its valid steps of ``|100 sigmoid(k x(t)) - 50|``, plus float32 eps.

        ``x(t)`` is the contact energy up to step ``t`` (touch times the object's displacement, summed over steps and
        over x, y, z; 0 while the gripper is outside ``workspace``) times the length of the step's displacement.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes holding the :meth:`episode_keys` entries.
            valid (torch.Tensor): bool ``[n, T]``, the steps before each episode's end; padding adds nothing.

        Returns:
            float64 ``[n]`` priorities, positive: an episode without contact stays drawable.
        """
        displacement = self._displacement(episodes, valid)
        energy = torch.cumsum(displacement.sum(-1) * self._touch(episodes, valid), dim=1)  # xyz summed first: commutes
        x = energy * self._in_workspace(episodes) * torch.linalg.vector_norm(displacement, dim=-1)
        centred = 100.0 * torch.sigmoid(self.k * x) - 50.0
        return centred.abs().sum(1) + FLOAT32_EPS

    def __repr__(self) -> str:
        return f"ReleasedCEBPSampler(k={self.k}, workspace={self.workspace}, n_episodes={self.n_episodes})"


class InitialCEBPSampler(_ContactEnergySampler):
    """CEBP as in the code's "Initial files" commit (the mocap Fetch): the contact energy in the workspace box, no
    sigmoid; IS weights as :class:`ReleasedCEBPSampler`'s, of exponent ``beta``.

    Args:
        beta (float, optional): the IS exponent. Defaults to ``0.7``, the commit's.
        workspace (tuple of two (x, y, z) tuples, optional): as :class:`ReleasedCEBPSampler`. Defaults to ``None``.
        touch_key, position_key, next_position_key, end_key (NestedKey, optional): as :class:`CEBPSampler`.
        next_observation_key (NestedKey, optional): as :class:`ReleasedCEBPSampler`.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.replay.samplers import InitialCEBPSampler
        >>> touch = torch.zeros(2, 50, 2)
        >>> touch[1] = 1.0  # only episode 1 touches
        >>> episodes = TensorDict({"achieved_goal": torch.zeros(2, 50, 3), "next": {
        ...     "achieved_goal": torch.rand(2, 50, 3), "touch": touch, "observation": torch.rand(2, 50, 25)}}, [2, 50])
        >>> InitialCEBPSampler().episode_priority(episodes, torch.ones(2, 50, dtype=torch.bool)).argmax().item()
        1
    """

    def __init__(self, *, beta: float = 0.7, **keys: Any) -> None:
        super().__init__(**keys)
        self.beta = checked("InitialCEBPSampler", "beta", beta)

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Each episode's sum over its valid steps of both pads' touch (0 while the gripper is outside ``workspace``)
        times the length of the object's displacement, plus float32 eps: no sigmoid.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes holding the :meth:`episode_keys` entries.
            valid (torch.Tensor): bool ``[n, T]``, the steps before each episode's end; padding adds nothing.

        Returns:
            float64 ``[n]`` priorities; every episode without contact has eps, so those with contact dominate.
        """
        distance = torch.linalg.vector_norm(self._displacement(episodes, valid), dim=-1)
        touch = self._touch(episodes, valid) * self._in_workspace(episodes)
        return (touch * distance).abs().sum(1) + FLOAT32_EPS

    def __repr__(self) -> str:
        return f"InitialCEBPSampler(beta={self.beta}, workspace={self.workspace}, n_episodes={self.n_episodes})"
