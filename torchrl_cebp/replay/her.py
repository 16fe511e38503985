"""Hindsight Experience Replay relabelling that composes with any sampler and any buffer transform."""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, Literal

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.sample_units import SampleUnit
from torchrl.data.replay_buffers.storages import Storage

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import episode_lengths, next_key, shared_length, stored_lengths
from torchrl_cebp.replay.samplers.base import require_key, split_index

STRATEGIES = ("future", "final", "episode", "past")


class HindsightRelabel(SampleUnit):
    """Replaces the goal of sampled transitions by a goal the episode achieved, before the buffer's transforms.

    Give one instance to a stock :class:`~torchrl.data.TensorDictReplayBuffer` over an episode storage (``ndim=2``)
    twice: as its ``sample_unit`` (it sees the drawn ``(episode, step)`` pairs and the storage) and as its
    ``collate_fn`` (it writes the new goals and rewards into the batch, before the transforms). Any sampler works,
    ours or TorchRL's. A coin of probability ``future_p`` per transition decides whether to relabel; the new goal is
    an achieved goal of the episode's valid steps, chosen by ``strategy`` (the :doc:`replay page </replay>` lists them,
    and compares this with :class:`torchrl.data.HERReplayBuffer`). Coins and goals draw from the buffer's generator.

    Args:
        reward_fn (Callable[[torch.Tensor, torch.Tensor], torch.Tensor]): vectorised sparse reward,
            ``[..., 3], [..., 3] -> [..., 1]`` (e.g. the env's ``compute_reward``). Its reward takes the stored
            reward's shape and dtype: ``[...]`` (gymnasium-robotics' form) is reshaped, a float one cast; a reward of
            another number of elements, or not of floats, is refused (``ValueError``).
        future_p (float, optional): probability to relabel a transition (0.8 is HER's replay_k=4).
            Defaults to ``0.8``.
        strategy (str, optional): ``"future"``, ``"final"``, ``"episode"`` or ``"past"``.
            Defaults to ``"future"``.
        goal_key (NestedKey, optional): the desired goal at the root; its ``"next"`` counterpart holds the
            next-state's. Defaults to ``"desired_goal"``.
        achieved_goal_key (NestedKey, optional): the achieved goal at the root; its ``"next"`` counterpart
            holds the next-state's, from which new goals are drawn. Defaults to ``"achieved_goal"``.
        reward_key (NestedKey, optional): where the recomputed reward goes. Defaults to ``("next", "reward")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row does.
            Defaults to ``("next", "done")``.
        relabelled_key (NestedKey or None, optional): a bool entry of the sample info telling which
            transitions were relabelled (``None`` to omit it). Defaults to ``"her_relabelled"``.
        success_key (NestedKey or None, optional): the next-state's success flag (the Fetch envs' ``is_success``).
            It tells the stored goal's success, not the relabelled goal's, so it is dropped from every drawn batch:
            the relabelled reward tells success. ``None`` keeps it as stored. Defaults to ``("next", "is_success")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl.envs import RewardScaling
        >>> from torchrl_cebp.replay import HindsightRelabel
        >>> T = 50
        >>> reward = lambda ag, g: -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()
        >>> episodes = TensorDict({"desired_goal": torch.zeros(4, T, 3),
        ...     "next": {"achieved_goal": torch.rand(4, T, 3), "desired_goal": torch.zeros(4, T, 3),
        ...              "reward": torch.zeros(4, T, 1)}}, [4, T])
        >>> her = HindsightRelabel(reward, future_p=1.0)
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2), dim_extend=0, batch_size=8,
        ...                             sample_unit=her, collate_fn=her.collate,
        ...                             transform=RewardScaling(loc=0.0, scale=10.0, in_keys=[("next", "reward")]))
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> bool((batch["desired_goal"] != 0).all()), set(batch["next", "reward"].unique().tolist()) <= {-10.0, 0.0}
        (True, True)
    """

    def __init__(
        self, reward_fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], *, future_p: float = 0.8,
        strategy: Literal["future", "final", "episode", "past"] = "future", goal_key: NestedKey = "desired_goal",
        achieved_goal_key: NestedKey = "achieved_goal", reward_key: NestedKey = ("next", "reward"),
        end_key: NestedKey = ("next", "done"), relabelled_key: NestedKey | None = "her_relabelled",
        success_key: NestedKey | None = ("next", "is_success"),
    ) -> None:
        if strategy not in STRATEGIES:
            raise ValueError(f"unknown HER strategy {strategy!r}; valid strategies: {list(STRATEGIES)}")
        if not 0.0 <= future_p <= 1.0:
            raise ValueError(f"future_p must lie in [0, 1], got {future_p}")
        self.reward_fn = reward_fn
        self.future_p = float(future_p)
        self.strategy = strategy
        self.goal_key = goal_key
        self.next_achieved_goal_key = next_key(achieved_goal_key)
        self.reward_key = reward_key
        self.end_key = end_key
        self.relabelled_key = relabelled_key
        self.success_key = success_key
        self._pending = threading.local()  # expand() -> collate() of one draw, per sampling thread
        self._collated = False  # whether a draw has reached collate(): the buffer calls it

    def relabel(
        self, episodes: TensorDictBase, rows: torch.Tensor, steps: torch.Tensor,
        generator: torch.Generator | None = None, lengths: torch.Tensor | int | None = None,
    ) -> dict[NestedKey, torch.Tensor]:
        """Relabels transitions ``(rows, steps)`` of ``[N, T]`` episodes as a draw does: their new entries and coin.

        ``lengths`` (of ``rows``, or one they share) default to the ``end_key`` flags'; ``generator`` to torch's RNG.
        """
        relabel, candidate = self._draw(episodes, rows, steps, generator, lengths)
        flat = torch.add(steps, rows, alpha=episodes.shape[1])
        stored_goal = require_key(episodes, self.goal_key, (None,)).flatten(0, 1).index_select(0, flat)
        achieved = episodes.get(self.next_achieved_goal_key).flatten(0, 1).index_select(0, flat)
        entries = self._relabelled(relabel, candidate, stored_goal, achieved,
                                   self._reward_layout(episodes, flat.shape, per_transition_dims=2))
        if self.relabelled_key is not None:
            entries[self.relabelled_key] = relabel
        return entries

    def _relabelled(
        self, relabel: torch.Tensor, candidate: torch.Tensor, stored_goal: torch.Tensor, next_achieved: torch.Tensor,
        stored_reward: tuple[torch.Size, torch.dtype] | None,
    ) -> dict[NestedKey, torch.Tensor]:
        """The goal and reward entries of transitions: ``candidate`` where ``relabel``, else their stored goal; the
        reward in the stored reward's ``(shape, dtype)`` if one is stored.

        The one place both :meth:`relabel` and the buffer's :meth:`collate` build them.
        """
        goal = torch.where(relabel.unsqueeze(-1), candidate, stored_goal)
        reward = self.reward_fn(next_achieved, goal)
        if stored_reward is not None:
            reward = self._as_stored(torch.as_tensor(reward), *stored_reward)
        return {self.goal_key: goal, next_key(self.goal_key): goal, self.reward_key: reward}

    def _reward_layout(self, data: TensorDictBase, transitions: torch.Size,
                       per_transition_dims: int) -> tuple[torch.Size, torch.dtype] | None:
        # The shape and dtype a relabelled reward of ``transitions`` takes: the stored reward's, after its
        # ``per_transition_dims`` leading dims; None where no reward is stored.
        stored = data.get(self.reward_key, None)
        return None if stored is None else (transitions + stored.shape[per_transition_dims:], stored.dtype)

    def _as_stored(self, reward: torch.Tensor, shape: torch.Size, dtype: torch.dtype) -> torch.Tensor:
        """``reward_fn``'s reward in the stored reward's shape and dtype: one of as many elements is reshaped (the
        ``[B]`` of gymnasium-robotics' ``compute_reward`` to ``[B, 1]``), a floating one cast; any other refused."""
        if reward.shape != shape:
            if reward.numel() != shape.numel():
                raise ValueError(f"HindsightRelabel's reward_fn returned a reward of shape {list(reward.shape)} for "
                                 f"{shape[0]} transitions, whose stored {self.reward_key!r} has shape {list(shape)}: "
                                 "return one reward per transition (e.g. vector_norm(..., keepdim=True))")
            reward = reward.reshape(shape)
        if reward.dtype != dtype:
            if not reward.is_floating_point():
                raise ValueError(f"HindsightRelabel's reward_fn returned {reward.dtype} rewards, whose stored "
                                 f"{self.reward_key!r} is {dtype}: return float rewards (e.g. -(distance > "
                                 "threshold).float())")
            reward = reward.to(dtype)
        return reward

    def _draw(
        self, episodes: TensorDictBase, rows: torch.Tensor, steps: torch.Tensor, generator: torch.Generator | None,
        lengths: torch.Tensor | int | None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The coin of each transition and the achieved goal it takes if the coin says relabel.

        The goal is ``(*next, achieved_goal_key)[e, j]``, state ``j + 1``: "future" draws ``j`` in ``[t, L - 1]``.
        """
        lengths = episode_lengths(episodes, self.end_key, rows) if lengths is None else lengths
        relabel = torch.rand(steps.shape, generator=generator) < self.future_p
        last = lengths - 1
        if self.strategy == "past":
            goal_steps = steps.clamp(max=last)
        elif self.strategy == "final":
            goal_steps = torch.zeros_like(steps).add_(last)
        else:
            # A step at or past its episode's end (the normaliser feed reads whole rows) has L - t <= 0: t + offset
            # stays >= L, and the clamp gives it the episode's last goal, as a clamp of L - t at 0 would.
            span = lengths if self.strategy == "episode" else lengths - steps
            goal_steps = torch.rand(steps.shape, generator=generator).mul_(span).long()
            if self.strategy == "future":
                goal_steps.add_(steps)
            goal_steps.clamp_(max=last)
        # A flat view + index_select: much cheaper than 2-D advanced indexing.
        next_achieved = require_key(episodes, self.next_achieved_goal_key, (None,)).flatten(0, 1)
        return relabel, next_achieved.index_select(0, goal_steps.add_(rows, alpha=episodes.shape[1]))

    # ---- the two hooks of a TorchRL buffer -----------------------------------------
    def expand(
        self, index: torch.Tensor | tuple, info: dict[str, Any], storage: Storage
    ) -> tuple[torch.Tensor | tuple, dict[str, Any]]:
        """The buffer's ``sample_unit`` hook: draws each drawn transition's coin and candidate goal, which
        :meth:`collate` then writes into the batch.

        Args:
            index (torch.Tensor or tuple): the sampler's draw, ``(rows, steps)`` or ``[B, 2]``.
            info (dict): the sampler's info, to which the relabelled flags are added under ``relabelled_key``.
            storage (Storage): the buffer's episode storage (``ndim=2``).

        Returns:
            ``(index, info)``: the transitions to read and ``info``. With ``strategy="past"`` each transition read is
            a step ``[0, t)`` of the drawn one's episode (step 0 for ``t = 0``), and the drawn step ``t`` gives the
            goal.

        Raises:
            ValueError: the storage is not an episode storage (``ndim=2``).
            RuntimeError: the previous draw never reached :meth:`collate`: the buffer lacks this instance as its
                ``collate_fn``.
        """
        if getattr(self._pending, "draw", None) is not None:
            # The buffer read no batch after the previous draw. Once a batch has reached collate(), the buffer is
            # known to call it, so that draw was interrupted (an error or Ctrl-C while the batch was read): drop it.
            self._pending.draw = None
            if not self._collated:
                raise RuntimeError("HindsightRelabel's previous draw was never written into its batch: give the "
                                   "buffer the same instance as collate_fn too, e.g. TensorDictReplayBuffer("
                                   "sample_unit=her, collate_fn=her.collate, ...). (If it has it, that first draw was "
                                   "interrupted before its batch was read; sample again.)")
        if getattr(storage, "ndim", 1) != 2:  # a flat storage's draws are no (episode, step) pairs to relabel within
            raise ValueError(f"HindsightRelabel takes its goals from the drawn transition's own episode, so it needs "
                             f"an episode storage of [episode, t] rows (ndim=2), got {type(storage).__name__} with "
                             f"ndim={getattr(storage, 'ndim', 1)}: use EpisodeStorage(capacity) (or "
                             "LazyTensorStorage(capacity, ndim=2)) and write [n_episodes, T] episodes with "
                             "dim_extend=0; a collector's frames need EpisodeWriter(max_episode_steps)")
        rows, steps = split_index(index)
        generator = _upstream.buffer_generator(storage)
        lengths = shared_length(storage, self.end_key)
        if lengths is None:
            lengths = stored_lengths(storage, rows, self.end_key)
        stored = _upstream.stored_tensordict(storage)
        require_key(stored, self.goal_key, (None,))  # collate() reads it from the batch
        relabel, candidate = self._draw(stored, rows, steps, generator, lengths)
        if self.relabelled_key is not None:
            info[self.relabelled_key] = relabel
        self._pending.draw = relabel, candidate
        if self.strategy == "past":  # the transition replayed precedes the drawn step, which gave the goal
            earlier = torch.rand(steps.shape, generator=generator, dtype=torch.float64).mul_(steps).long()
            index = (rows, earlier) if isinstance(index, tuple) else torch.stack([rows, earlier], -1)
        return index, info

    def collate(self, data: TensorDictBase) -> TensorDictBase:
        """The buffer's ``collate_fn``: writes the goals and rewards of the last :meth:`expand` into ``data``.

        ``data`` already holds each transition's stored goal and achieved goal: no second read of the storage.
        """
        if data.ndim > 1:  # rb[index] reads stored [episode, t] rows, not relabelled; a draw reads [B] transitions
            return data
        draw = getattr(self._pending, "draw", None)
        if draw is None:
            raise RuntimeError(f"HindsightRelabel.collate got a batch of shape {list(data.shape)} without a draw of "
                               "its own: give the buffer the same instance as sample_unit too, as in "
                               "TensorDictReplayBuffer(sample_unit=her, ...)")
        self._pending.draw = None
        self._collated = True
        entries = self._relabelled(*draw, data.get(self.goal_key), data.get(self.next_achieved_goal_key),
                                   self._reward_layout(data, data.shape, per_transition_dims=len(data.shape)))
        for key, value in entries.items():
            data.set(key, value)
        if self.success_key is not None and data.get(self.success_key, None) is not None:
            del data[self.success_key]  # the stored goal's success: wrong for a relabelled one
        return data

    # A thread-local cannot be pickled; a pending draw belongs to the thread between a buffer's expand and its
    # collate, so a copy (deepcopy, pickle, a collector's worker) starts with none.
    def __getstate__(self) -> dict[str, Any]:
        return {key: value for key, value in self.__dict__.items() if key != "_pending"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._pending = threading.local()

    def __repr__(self) -> str:
        return f"HindsightRelabel(strategy={self.strategy!r}, future_p={self.future_p})"

