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
    ends = end_flags(episodes, end_key, rows)
    if ends is None:
        n_rows, row_length = episodes.shape[:2]
        return torch.full((n_rows if rows is None else rows.numel(),), row_length, dtype=torch.long)
    first_end = ends.to(torch.uint8).argmax(1)
    return torch.where(ends.any(1), first_end + 1, ends.shape[1])


def end_flags(
    episodes: TensorDictBase, end_key: NestedKey = ("next", "done"), rows: torch.Tensor | None = None
) -> torch.Tensor | None:
    """``[n, T]``: whether each step of the rows (of ``rows``, if given) ends an episode; ``None`` without ``end_key``.

    Examples:
        >>> from tensordict import TensorDict
        >>> done = torch.zeros(2, 4, 1, dtype=torch.bool)
        >>> done[0, 1] = True
        >>> end_flags(TensorDict({"next": {"done": done}}, [2, 4])).int().tolist()
        [[0, 1, 0, 0], [0, 0, 0, 0]]
    """
    ends = episodes.get(end_key, None)
    if ends is None:
        return None
    if rows is not None:
        ends = ends.index_select(0, rows)
    return ends.reshape(*ends.shape[:2], -1).any(-1)


def require_time_at(data: TensorDictBase, dim: int) -> None:
    """Refuses a batch whose ``"time"`` dimension (TorchRL's collectors and ``rollout`` name it) is not ``dim``.

    Examples:
        >>> from tensordict import TensorDict
        >>> frames = TensorDict(batch_size=[12, 50], names=[None, "time"])
        >>> require_time_at(frames, 1)
        >>> require_time_at(frames.transpose(0, 1), 1)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: the batch of shape [50, 12] has its 'time' dimension at 0, not 1: ...dim_extend=0
    """
    names = data.names
    if "time" in names and names.index("time") != dim:
        raise ValueError(
            f"the batch of shape {list(data.shape)} has its 'time' dimension at {names.index('time')}, not {dim}: "
            "the buffer transposed it (TorchRL's default dim_extend); build it with dim_extend=0"
        )


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
