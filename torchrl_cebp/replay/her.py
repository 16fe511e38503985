"""Hindsight Experience Replay relabelling that composes with any sampler."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

import torch
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.sample_units import SampleUnit
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp.replay.samplers.base import split_index

RewardFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
STRATEGIES = ("future", "final", "episode")


class HindsightRelabel(SampleUnit):
    """Replaces the desired goal of sampled transitions by a goal the episode achieved.

    Plugged into a stock :class:`~torchrl.data.TensorDictReplayBuffer` as its
    ``sample_unit`` over an episode storage (``ndim=2``), it works with any
    sampler, ours or TorchRL's. For each sampled transition ``(e, t)`` a coin
    with probability ``future_p`` decides whether to relabel; the new goal is
    the achieved goal of a next-state of the same episode:

    * ``"future"``: state ``t' = t + 1 + floor(U * (T - t))``, i.e. a *later*
      next-state, never the current state, possibly the final one (baselines' HER);
    * ``"final"``: the episode's final state;
    * ``"episode"``: any next-state of the episode, uniformly.

    ``desired_goal`` and ``("next", "desired_goal")`` get the new goal and
    ``("next", "reward")`` is recomputed for the whole batch in one call of
    ``reward_fn(achieved_goal, desired_goal)`` (e.g. the env's ``compute_reward``).
    A TorchRL sample unit is used rather than a transform because a buffer's
    transforms run before the sampled indices are known, and relabelling needs
    them to reach later steps of the same episode.

    Args:
        reward_fn: vectorised sparse reward, ``[..., 3], [..., 3] -> [..., 1]``.
        future_p: probability to relabel a transition (0.8 is HER's replay_k=4).
        strategy: ``"future"``, ``"final"`` or ``"episode"``.
        achieved_goal_key, desired_goal_key: keys of the goals at the root; the
            ``"next"`` counterparts are used for next-states and rewards.
        reward_key: where the recomputed reward goes.
        relabelled_key: a bool entry telling which transitions were relabelled
            (``None`` to omit it).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer, RandomSampler
        >>> from torchrl_cebp.replay import HindsightRelabel
        >>> T = 50
        >>> reward = lambda ag, g: -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()
        >>> episodes = TensorDict({"desired_goal": torch.zeros(4, T, 3),
        ...     "next": {"achieved_goal": torch.rand(4, T, 3), "desired_goal": torch.zeros(4, T, 3),
        ...              "reward": torch.zeros(4, T, 1)}}, [4, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2), dim_extend=0,
        ...                             batch_size=8, sample_unit=HindsightRelabel(reward, future_p=1.0))
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> bool((batch["desired_goal"] != 0).all())
        True
    """

    def __init__(
        self,
        reward_fn: RewardFn,
        *,
        future_p: float = 0.8,
        strategy: Literal["future", "final", "episode"] = "future",
        achieved_goal_key: NestedKey = "achieved_goal",
        desired_goal_key: NestedKey = "desired_goal",
        reward_key: NestedKey = ("next", "reward"),
        relabelled_key: NestedKey | None = "her_relabelled",
        generator: torch.Generator | None = None,
    ) -> None:
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown HER strategy {strategy!r}; valid strategies: {list(STRATEGIES)}")
        if not 0.0 <= future_p <= 1.0:
            raise ValueError(f"future_p must lie in [0, 1], got {future_p}")
        self.reward_fn = reward_fn
        self.future_p = float(future_p)
        self.strategy = strategy
        self.desired_goal_key = desired_goal_key
        self.next_achieved_goal_key = _next(achieved_goal_key)
        self.next_desired_goal_key = _next(desired_goal_key)
        self.reward_key = reward_key
        self.relabelled_key = relabelled_key
        self._rng = generator

    def goal_steps(self, steps: torch.Tensor, episode_length: int) -> torch.Tensor:
        """Index ``j`` into the ``("next", ...)`` entries whose achieved goal becomes the new goal.

        ``("next", key)[e, j]`` is state ``j + 1``, so "future" draws ``j`` in ``[t, T - 1]``.
        """
        if self.strategy == "final":
            return torch.full_like(steps, episode_length - 1)
        uniform = torch.rand(steps.shape, generator=self._rng)
        if self.strategy == "episode":
            return (uniform * episode_length).long().clamp_(max=episode_length - 1)
        offset = (uniform * (episode_length - steps)).long()
        return (steps + offset).clamp_(max=episode_length - 1)

    def expand(
        self, index: torch.Tensor | tuple, info: dict[str, Any], storage: Storage
    ) -> tuple[torch.Tensor | tuple, dict[str, Any]]:
        rows, steps = split_index(index)
        data = storage._storage
        episode_length = data.shape[1]
        # Flat views + index_select: much cheaper than 2-D advanced indexing.
        next_achieved = data.get(self.next_achieved_goal_key).flatten(0, 1)
        stored_goal = data.get(self.desired_goal_key).flatten(0, 1)
        first_step = rows * episode_length
        relabel = torch.rand(steps.shape, generator=self._rng) < self.future_p
        goal_steps = self.goal_steps(steps, episode_length)
        goal = torch.where(
            relabel.unsqueeze(-1),
            next_achieved.index_select(0, first_step + goal_steps),
            stored_goal.index_select(0, first_step + steps),
        )
        info[self.desired_goal_key] = goal
        info[self.next_desired_goal_key] = goal
        info[self.reward_key] = self.reward_fn(next_achieved.index_select(0, first_step + steps), goal)
        if self.relabelled_key is not None:
            info[self.relabelled_key] = relabel
        return index, info

    def __repr__(self) -> str:
        return f"HindsightRelabel(strategy={self.strategy!r}, future_p={self.future_p})"


def _next(key: NestedKey) -> tuple[str, ...]:
    return ("next", *((key,) if isinstance(key, str) else key))
