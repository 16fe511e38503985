"""Replay-buffer transforms that must see HER's relabelled goals."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from tensordict.utils import NestedKey
from torchrl.envs import CatTensors, Compose

from torchrl_cebp.replay.episodes import next_key


def replay_cat_tensors(
    in_keys: Sequence[NestedKey], out_key: NestedKey = "observation_vector", *, sort: bool = False, **kwargs: Any
) -> Compose:
    """TorchRL's :class:`~torchrl.envs.CatTensors` as a replay buffer's ``transform``: on the root and on ``"next"``.

    Concatenate the observation and the goal here, not in the env. HER writes the new goal into
    the sampled batch, after storage and before the buffer's transforms; a vector concatenated in the
    env was stored with the old goal and stays stale for every relabelled transition. An env's
    ``CatTensors`` builds the vector on reset and step, that is on the root and on ``"next"``;
    a buffer transform sees both in one batch, so this is two ``CatTensors`` with the same
    arguments, and it builds the vector the env's transform would. The buffer runs it after HER's
    ``collate_fn``, and overwrites a vector the env stored.

    Args:
        in_keys (sequence of NestedKey): the entries to concatenate, in this order.
        out_key (NestedKey, optional): the concatenated entry. Defaults to ``"observation_vector"``.
        sort (bool, optional): whether to sort ``in_keys`` first, as ``CatTensors`` does by default.
            Defaults to ``False``: the vector keeps the order given (``["observation", "desired_goal"]``
            puts the goal last).
        **kwargs: the other arguments of ``CatTensors`` (``dim``, ``del_keys``, ...).

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay import HindsightRelabel
        >>> T = 50
        >>> reward = lambda ag, g: -(torch.linalg.vector_norm(ag - g, dim=-1, keepdim=True) > 0.05).float()
        >>> state = {"observation": torch.zeros(4, T, 25), "achieved_goal": torch.rand(4, T, 3),
        ...          "desired_goal": torch.zeros(4, T, 3)}
        >>> episodes = TensorDict({**state, "next": {**state, "reward": torch.zeros(4, T, 1)}}, [4, T])
        >>> her = HindsightRelabel(reward, future_p=1.0)
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2), dim_extend=0, batch_size=8,
        ...     sample_unit=her, collate_fn=her.collate,
        ...     transform=replay_cat_tensors(["observation", "desired_goal"], "observation_goal"))
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> batch["observation_goal"].shape, batch["next", "observation_goal"].shape
        (torch.Size([8, 28]), torch.Size([8, 28]))
        >>> bool((batch["observation_goal"][:, 25:] != 0).all())  # the relabelled goals, not the stored zeros
        True
    """
    return Compose(
        CatTensors(in_keys, out_key, sort=sort, **kwargs),
        CatTensors([next_key(key) for key in in_keys], next_key(out_key), sort=sort, **kwargs),
    )
