"""HER's exploration: epsilon-random actions, otherwise Gaussian noise on the policy's."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, exploration_type


class HERExploration(TensorDictModuleBase):
    """Perturbs the action written by the policy, as baselines' HER does.

    With probability ``random_eps`` the action is replaced by a uniform random one,
    otherwise ``N(0, noise_std)`` noise is added; the result is clipped to
    ``[low, high]``. Acts only under the random exploration type (the collectors'
    default), so ``set_exploration_type(ExplorationType.DETERMINISTIC)`` gives the
    plain policy for test episodes. Place it after the actor in a
    :class:`~tensordict.nn.TensorDictSequential`.

    Draws from ``generator`` (torch's global one when ``None``): with its own generator,
    the exploration stream is reproducible wherever the episodes are collected.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl.envs.utils import ExplorationType, set_exploration_type
        >>> explore = HERExploration()
        >>> td = TensorDict({"action": torch.zeros(1000, 4)}, [1000])
        >>> bool(explore(td.clone())["action"].abs().max() <= 1)
        True
        >>> with set_exploration_type(ExplorationType.DETERMINISTIC):
        ...     bool((explore(td.clone())["action"] == 0).all())
        True
    """

    def __init__(
        self,
        *,
        random_eps: float = 0.3,
        noise_std: float = 0.2,
        low: float = -1.0,
        high: float = 1.0,
        action_key: str = "action",
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.in_keys = [action_key]
        self.out_keys = [action_key]
        self.random_eps = random_eps
        self.noise_std = noise_std
        self.low = low
        self.high = high
        self.generator = generator

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        if exploration_type() not in (ExplorationType.RANDOM, None):
            return td
        action = td.get(self.in_keys[0])
        noise = torch.randn(action.shape, generator=self.generator, device=action.device, dtype=action.dtype)
        noisy = (action + self.noise_std * noise).clamp(self.low, self.high)
        uniform = torch.empty_like(action).uniform_(self.low, self.high, generator=self.generator)
        replace = torch.rand(action.shape[:-1] + (1,), generator=self.generator, device=action.device) < self.random_eps
        td.set(self.out_keys[0], torch.where(replace, uniform, noisy))
        return td
