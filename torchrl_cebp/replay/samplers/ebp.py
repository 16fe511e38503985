"""Energy-Based hindsight experience Prioritization (EBP, Zhao & Tresp 2018)."""
from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.replay.samplers.base import FLOAT32_EPS, EpisodePrioritySampler, checked, episode_positions

GRAVITY = 9.81
MASS = 1.0
STEP_SECONDS = 0.04  # 20 substeps of 2 ms: the Fetch control step


class EBPSampler(EpisodePrioritySampler):
    """Episodes drawn by the object's trajectory energy, its clipped increases of potential and kinetic energy.

    The formula is on the :doc:`samplers page </samplers>`. No importance-sampling weights.

    Args:
        clip_energy (float, optional): per-step clip (0.5 for PickAndPlace in the paper). Defaults to ``999.0``.
        temperature (float, optional): sets the exponent ``1 / (temperature + 0.01)``. Defaults to ``1.0``.
        w_potential (float, optional): weight of the potential energy term. Defaults to ``1.0``.
        w_kinetic (float, optional): weight of the kinetic energy term. Defaults to ``1.0``.
        position_key (NestedKey, optional): the object's position before a step. Defaults to ``"achieved_goal"``.
        next_position_key (NestedKey, optional): its position after a step. Defaults to ``("next", "achieved_goal")``.
        end_key (NestedKey, optional): the flag that ends an episode before its row. Defaults to ``("next", "done")``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.replay.samplers import EBPSampler
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(10 * 50, ndim=2), sampler=EBPSampler(clip_energy=0.5),
        ...                             batch_size=4, dim_extend=0)
        >>> _ = rb.extend(TensorDict({"achieved_goal": torch.rand(3, 50, 3),
        ...                           "next": {"achieved_goal": torch.rand(3, 50, 3)}}, [3, 50]))
        >>> rb.sample().shape
        torch.Size([4])
    """

    def __init__(
        self, clip_energy: float = 999.0, temperature: float = 1.0, *, w_potential: float = 1.0,
        w_kinetic: float = 1.0, position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"), end_key: NestedKey = ("next", "done"),
    ) -> None:
        super().__init__(end_key)
        self.clip_energy = checked("EBPSampler", "clip_energy", clip_energy, exclusive=True)
        self.temperature = checked("EBPSampler", "temperature", temperature)
        self.w_potential = checked("EBPSampler", "w_potential", w_potential)
        self.w_kinetic = checked("EBPSampler", "w_kinetic", w_kinetic)
        self.position_key = position_key
        self.next_position_key = next_position_key

    def episode_keys(self) -> dict[NestedKey, tuple[int | None, ...]]:
        """The entries read: the object's position before and after each step, ``(3,)`` each."""
        return {self.position_key: (3,), self.next_position_key: (3,)}

    def episode_priority(self, episodes: TensorDictBase, valid: torch.Tensor) -> torch.Tensor:
        """Each episode's trajectory energy raised to ``1 / (temperature + 0.01)``, plus float32 eps.

        The trajectory energy sums, over the valid steps, each step's increase of the object's energy, clipped to
        ``[0, clip_energy]``: ``w_potential`` times its potential energy above its first height plus ``w_kinetic``
        times its kinetic energy (mass 1, steps of 0.04 s). The eps keeps a buffer of motionless episodes drawable,
        uniformly.

        Args:
            episodes (TensorDictBase): ``[n, T]`` episodes holding the :meth:`episode_keys` entries.
            valid (torch.Tensor): bool ``[n, T]``, the steps before each episode's end; padding adds nothing.
        """
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        height = positions[:, 1:, 2] - positions[:, :1, 2]
        velocity = positions.diff(dim=1) / STEP_SECONDS
        energy = self.w_potential * GRAVITY * MASS * height + self.w_kinetic * 0.5 * MASS * velocity.pow(2).sum(-1)
        increase = torch.cat([energy[:, :1], energy.diff(dim=1)], dim=1)
        trajectory_energy = increase.clamp(0.0, self.clip_energy).where(valid, 0.0).sum(1)  # padding's NaN * 0 is NaN
        # eps keeps a buffer of motionless episodes drawable (uniformly) instead of all-zero.
        return trajectory_energy.pow(1.0 / (self.temperature + 0.01)) + FLOAT32_EPS

    def __repr__(self) -> str:
        return (f"EBPSampler(clip_energy={self.clip_energy}, temperature={self.temperature}, "
                f"n_episodes={self.n_episodes})")
