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

    Concatenate the observation and the goal here, not in the env: the buffer runs its transform after HER wrote
    the new goal, and overwrites a stale vector the env stored (see the :doc:`replay page </replay>`). It is two
    ``CatTensors`` with the same arguments, building on both levels the vector the env's transform would.

    Args:
        in_keys (sequence of NestedKey): the entries to concatenate, in this order.
        out_key (NestedKey, optional): the concatenated entry. Defaults to ``"observation_vector"``.
        sort (bool, optional): whether to sort ``in_keys`` first, as ``CatTensors`` does by default.
            Defaults to ``False``: the vector keeps the order given (the goal last after the observation).
        **kwargs: the other arguments of ``CatTensors`` (``dim``, ``del_keys``, ...).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> state = {"observation": torch.zeros(8, 25), "desired_goal": torch.ones(8, 3)}
        >>> cat = replay_cat_tensors(["observation", "desired_goal"], "observation_goal")
        >>> batch = cat(TensorDict({**state, "next": state}, [8]))
        >>> batch["observation_goal"].shape, batch["next", "observation_goal"][0, 24:].tolist()
        (torch.Size([8, 28]), [0.0, 1.0, 1.0, 1.0])
    """
    return Compose(
        CatTensors(in_keys, out_key, sort=sort, **kwargs),
        CatTensors([next_key(key) for key in in_keys], next_key(out_key), sort=sort, **kwargs),
    )
