"""What every part of the replay reads from episode rows: their valid length, and their "next" keys."""
from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data.replay_buffers.storages import Storage, TensorStorage

from torchrl_cebp import _upstream


def next_key(key: NestedKey) -> tuple[str, ...]:
    """``("next", *key)``: where TorchRL keeps the next-state's entry of ``key``."""
    return ("next", *((key,) if isinstance(key, str) else key))


def episode_lengths(
    episodes: TensorDictBase, end_key: NestedKey = ("next", "done"), rows: torch.Tensor | None = None
) -> torch.Tensor:
    """Valid steps of each episode row: up to and including its first ``end_key`` flag, else the whole row.

    Steps after the first flag are padding: no sampler draws them and HER takes no goal from them.

    Args:
        episodes (TensorDictBase): episode rows ``[n, T]``.
        end_key (NestedKey, optional): the flag that ends an episode. Defaults to ``("next", "done")``; without
            it every row is whole.
        rows (torch.Tensor, optional): restricts the answer to those rows of ``episodes`` (shape
            ``[len(rows)]``). Defaults to ``None`` (all rows).

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
    return lengths_of_ends(ends)


def lengths_of_ends(ends: torch.Tensor) -> torch.Tensor:
    """Valid steps of each row of ``[n, T]`` end flags (:func:`end_flags`): up to its first flag, else ``T``."""
    flagged, first = ends.max(1)  # one pass: whether a row has a flag, and where its first one is
    return torch.where(flagged, first + 1, ends.shape[1])


def end_flags(
    episodes: TensorDictBase, end_key: NestedKey = ("next", "done"), rows: torch.Tensor | None = None
) -> torch.Tensor | None:
    """``[n, T]``: whether each step of the rows (``rows``, if given) ends an episode; ``None`` without ``end_key``."""
    ends = episodes.get(end_key, None)
    if ends is None:
        return None
    if rows is not None:
        ends = ends.index_select(0, rows)
    return ends.any(-1) if ends.ndim == 3 else ends.reshape(*ends.shape[:2], -1).any(-1)


def stored_lengths(storage: Storage, rows: torch.Tensor, end_key: NestedKey = ("next", "done")) -> torch.Tensor:
    """Valid steps of the episodes in ``rows`` of any ``ndim=2`` storage: the one way samplers, PER and HER learn them.

    An episode storage that cuts at the same ``end_key`` keeps them; any other storage is read at the rows' flags.
    """
    if getattr(storage, "end_key", None) == end_key and hasattr(storage, "valid_lengths"):
        return storage.valid_lengths(rows)
    if isinstance(storage, TensorStorage):  # the rows' flags alone
        return episode_lengths(_upstream.stored_tensordict(storage), end_key, rows)
    return episode_lengths(storage.get(rows), end_key)


def shared_length(storage: Storage, end_key: NestedKey = ("next", "done")) -> int | None:
    """The valid length all episodes of ``storage`` share, if an episode storage cutting at ``end_key`` knows one.

    Lets a draw skip the per-row lengths in the usual case of episodes that all run a fixed length.
    """
    if getattr(storage, "end_key", None) == end_key and hasattr(storage, "common_length"):
        return storage.common_length()
    return None


def require_time_at(
    data: TensorDictBase, dim: int, dim_extends: Sequence[int] | Callable[[], Sequence[int]] = ()
) -> None:
    """Refuses a batch whose ``"time"`` dimension (TorchRL's collectors and ``rollout`` name it) is not ``dim``.

    ``dim_extends`` (or a function giving them, called only to word the error) are the ``dim_extend`` of the
    buffers writing it: they tell a batch the buffer transposed from one laid out ``[T, envs]``.
    """
    names = data.names
    if "time" in names and names.index("time") != dim:
        dim_extends = dim_extends() if callable(dim_extends) else dim_extends
        transposed_by_buffer = "the buffer transposed it (its dim_extend is not 0): build it with dim_extend=0"
        laid_out = (f"the batch is laid out with time first; give it with time last, e.g. "
                    f"batch.transpose({names.index('time')}, {dim})")
        if not dim_extends:
            cause = f"either {transposed_by_buffer}, or {laid_out}"
        elif any(extend != 0 for extend in dim_extends):
            cause = transposed_by_buffer
        else:
            cause = laid_out
        raise ValueError(f"the batch of shape {list(data.shape)} has its 'time' dimension at {names.index('time')}, "
                         f"not {dim}: {cause}")


def valid_steps(lengths: torch.Tensor, row_length: int) -> torch.Tensor:
    """``[n, T]`` mask of the steps inside each episode's valid length (``lengths``, shape ``[n]``)."""
    return torch.arange(row_length) < lengths.unsqueeze(-1)


def common_length(lengths: torch.Tensor) -> int | None:
    """The length all of ``lengths`` share, else ``None`` (also for none): draws then need no per-row lengths."""
    if lengths.numel() == 0 or not bool((lengths == lengths[0]).all()):
        return None
    return int(lengths[0])
