"""What every part of the replay reads from episode rows: their valid length, and their "next" keys."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey


def next_key(key: NestedKey) -> tuple[str, ...]:
    """``("next", *key)``: where TorchRL keeps the next-state's entry of ``key``.

    Examples:
        >>> next_key("achieved_goal")
        ('next', 'achieved_goal')
    """
    return ("next", *((key,) if isinstance(key, str) else key))


def episode_lengths(
    episodes: TensorDictBase, end_key: NestedKey = ("next", "done"), rows: torch.Tensor | None = None
) -> torch.Tensor:
    """Valid steps of each episode row: up to and including its first ``end_key`` flag, else the whole row.

    Steps after the first flag are padding: no sampler draws them and HER takes no goal from them.
    ``rows`` restricts the answer to those rows of ``episodes`` (shape ``[len(rows)]``).

    Examples:
        >>> from tensordict import TensorDict
        >>> done = torch.zeros(3, 50, 1, dtype=torch.bool)
        >>> done[0, 19] = done[1, 49] = True  # episode 0 ended after 20 steps; episode 2 never ended
        >>> episode_lengths(TensorDict({"next": {"done": done}}, [3, 50])).tolist()
        [20, 50, 50]
    """
    n_rows, row_length = episodes.shape[:2]
    n = n_rows if rows is None else rows.numel()
    ends = episodes.get(end_key, None)
    if ends is None:
        return torch.full((n,), row_length, dtype=torch.long)
    if rows is not None:
        ends = ends.index_select(0, rows)
    ends = ends.reshape(n, row_length, -1).any(-1)
    first_end = ends.to(torch.uint8).argmax(1)
    return torch.where(ends.any(1), first_end + 1, row_length)


def valid_steps(lengths: torch.Tensor, row_length: int) -> torch.Tensor:
    """``[n, T]`` mask of the steps inside each episode's valid length.

    Examples:
        >>> valid_steps(torch.tensor([2, 4]), 4).int().tolist()
        [[1, 1, 0, 0], [1, 1, 1, 1]]
    """
    return torch.arange(row_length) < lengths.unsqueeze(-1)


def common_length(lengths: torch.Tensor) -> int | None:
    """The length all of ``lengths`` share, else ``None`` (also for none): draws then need no per-row lengths.

    Examples:
        >>> common_length(torch.tensor([50, 50])), common_length(torch.tensor([50, 7]))
        (50, None)
    """
    if lengths.numel() == 0 or not bool((lengths == lengths[0]).all()):
        return None
    return int(lengths[0])
