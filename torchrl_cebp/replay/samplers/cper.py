"""Contact Prioritized Experience Replay (CPER, Vulin et al. 2021)."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.replay.episodes import episode_lengths, valid_steps
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler, checked, require_key


class CPERSampler(EpisodePrioritySampler):
    """Steps after the episode's cumulative touch passes a threshold weigh ``lam``, others 1: an episode is drawn in
    proportion to the sum of its step weights, and a step in it by the same weights. No importance-sampling weights.

    Args:
        threshold (float, optional): cumulative touch (left + right) above which a step is contact-rich.
            Defaults to ``1.0``.
        lam (float, optional): weight of a contact-rich step (``lambda`` in the paper). Defaults to ``10.0``.
        touch_key (NestedKey, optional): both finger pads' touch, ``[T, 2]``. Defaults to ``("next", "touch")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import CPERSampler
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2), sampler=CPERSampler(),
        ...                             batch_size=4, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"next": {"touch": torch.rand(3, 50, 2)}}, [3, 50]))
        >>> rb.sample().shape
        torch.Size([4])
    """

    def __init__(
        self, threshold: float = 1.0, lam: float = 10.0, *, touch_key: NestedKey = ("next", "touch"),
        end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(end_key)
        self.threshold = checked("CPERSampler", "threshold", threshold)
        self.lam = checked("CPERSampler", "lam", lam, exclusive=True)
        self.touch_key = touch_key

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        """The one entry read: both pads' touch, ``(2,)`` per step."""
        return {self.touch_key: (2,)}

    def check_episodes(self, episodes: TensorDictBase) -> None:
        """Refuses episodes whose valid steps' touch is not finite, before an episode storage stores them."""
        self._touch(episodes)

    def _touch(self, episodes: TensorDictBase, valid: torch.Tensor | None = None) -> torch.Tensor:
        touch = require_key(episodes, self.touch_key, (2,)).sum(-1, dtype=torch.float64)
        if bool(touch.isfinite().all()):  # the usual episode: no valid steps to find
            return touch
        valid = valid_steps(episode_lengths(episodes, self.end_key), episodes.shape[1]) if valid is None else valid
        unreadable = valid & ~touch.isfinite()  # NaN never passes the threshold: every later step would weigh 1
        if unreadable.any():
            raise ValueError(f"CPERSampler: touch {self.touch_key!r} is {touch[unreadable].tolist()} at the (episode, "
                             f"step) {unreadable.nonzero().tolist()}: its step weights need finite touch")
        return touch

    def step_weights(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Each step's weight: ``lam`` once the episode's cumulative touch exceeds ``threshold``, else 1; 0 on padding.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes holding the touch entry.
            valid (torch.Tensor): bool ``[n, T]``, the steps before each episode's end.

        Raises:
            ValueError: a valid step's touch is NaN or infinite.
        """
        rich = torch.cumsum(self._touch(episodes, valid), dim=1) > self.threshold
        return torch.where(rich, self.lam, 1.0) * valid

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """The sum of each episode's :meth:`step_weights`, ``[n]``."""
        return self.step_weights(episodes, valid).sum(1)

    def __repr__(self) -> str:
        return f"CPERSampler(threshold={self.threshold}, lam={self.lam}, n_episodes={self.n_episodes})"
