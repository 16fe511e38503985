"""Running mean/std normalisation of observations and goals, as in baselines' HER."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn


class RunningNormalizer(nn.Module):
    """Normalises inputs by a running mean and standard deviation, then clips.

    The statistics are exact running sums (kept in float64 so that millions of
    updates do not drift), so the result does not depend on how the data was
    split into updates. The standard deviation is floored at ``eps``.

    Args:
        size (int): the size of the last dimension of the inputs.
        eps (float, optional): the smallest standard deviation used. Defaults to ``0.01``.
        clip (float, optional): the normalised values are clipped to ``[-clip, clip]``. Defaults to ``5.0``.

    Examples:
        >>> norm = RunningNormalizer(2)
        >>> norm.update(torch.tensor([[0.0, 10.0], [2.0, 10.0]]))
        >>> norm.mean
        tensor([ 1., 10.])
        >>> norm(torch.tensor([[1.0, 10.0], [3.0, 100.0]]))
        tensor([[0., 0.],
                [2., 5.]])
    """

    def __init__(self, size: int, eps: float = 0.01, clip: float = 5.0) -> None:
        super().__init__()
        self.eps = eps
        self.clip = clip
        self.register_buffer("sum", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("sumsq", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(size))
        self.register_buffer("std", torch.ones(size))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Adds the rows of ``x`` to the statistics.

        Args:
            x (torch.Tensor): ``[..., size]``, any leading shape.
        """
        x = x.reshape(-1, self.sum.shape[-1]).to(self.sum)
        self.sum += x.sum(0)
        self.sumsq += x.square().sum(0)
        self.count += x.shape[0]
        mean = self.sum / self.count
        var = self.sumsq / self.count - mean.square()
        self.mean.copy_(mean)
        self.std.copy_(var.clamp_min(self.eps**2).sqrt())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` normalised by the current statistics and clipped.

        Args:
            x (torch.Tensor): ``[..., size]``.
        """
        return ((x - self.mean) / self.std).clamp(-self.clip, self.clip)


class ObsGoalNormalizer(TensorDictModuleBase):
    """Writes the normalised ``[observation, goal]`` input of the actor and critic.

    Observation and goal are first clipped to ``+-raw_clip`` (baselines' ``clip_obs``),
    then normalised by their own :class:`RunningNormalizer`. Apply it to a batch and to
    its ``"next"`` sub-tensordict before the loss; inside a policy it runs on each step.
    The actor and critic keep no copy of the statistics, so their target networks
    always see the current ones, as in baselines.

    Args:
        obs_dim (int): the observation size.
        goal_dim (int): the goal size.
        eps (float, optional): see :class:`RunningNormalizer` (keyword only). Defaults to ``0.01``.
        clip (float, optional): see :class:`RunningNormalizer` (keyword only). Defaults to ``5.0``.
        raw_clip (float, optional): the raw values are clipped to ``[-raw_clip, raw_clip]`` first
            (keyword only). Defaults to ``200.0``.
        obs_key (str, optional): the observation's key (keyword only). Defaults to ``"observation"``.
        goal_key (str, optional): the goal's key (keyword only). Defaults to ``"desired_goal"``.
        out_key (str, optional): where the concatenated, normalised input is written (keyword only).
            Defaults to ``"agent_input"``.

    Examples:
        >>> from tensordict import TensorDict
        >>> norm = ObsGoalNormalizer(obs_dim=25, goal_dim=3)
        >>> td = TensorDict({"observation": torch.randn(8, 25), "desired_goal": torch.randn(8, 3)}, [8])
        >>> norm.update(td)
        >>> norm(td)["agent_input"].shape
        torch.Size([8, 28])
    """

    def __init__(
        self,
        obs_dim: int,
        goal_dim: int,
        *,
        eps: float = 0.01,
        clip: float = 5.0,
        raw_clip: float = 200.0,
        obs_key: str = "observation",
        goal_key: str = "desired_goal",
        out_key: str = "agent_input",
    ) -> None:
        super().__init__()
        self.in_keys = [obs_key, goal_key]
        self.out_keys = [out_key]
        self.raw_clip = raw_clip
        self.obs = RunningNormalizer(obs_dim, eps, clip)
        self.goal = RunningNormalizer(goal_dim, eps, clip)

    def _raw(self, td: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        obs_key, goal_key = self.in_keys
        return (
            td.get(obs_key).clamp(-self.raw_clip, self.raw_clip),
            td.get(goal_key).clamp(-self.raw_clip, self.raw_clip),
        )

    def update(self, td: TensorDictBase) -> None:
        """Adds the observations and goals of ``td`` to the statistics.

        Args:
            td (TensorDictBase): holds the observation and goal keys, any batch size.
        """
        obs, goal = self._raw(td)
        self.obs.update(obs)
        self.goal.update(goal)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        """Writes the normalised ``[observation, goal]`` into ``td`` at ``out_key``.

        Args:
            td (TensorDictBase): holds the observation and goal keys.
        """
        obs, goal = self._raw(td)
        td.set(self.out_keys[0], torch.cat([self.obs(obs), self.goal(goal)], -1))
        return td
