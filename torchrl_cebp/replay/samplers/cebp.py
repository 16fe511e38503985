"""Contact Energy Based Prioritization (CEBP)."""
from __future__ import annotations

from typing import Literal

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_cebp.replay.samplers.base import (
    FLOAT32_EPS,
    EpisodePrioritySampler,
    episode_positions,
    require_key,
)

# Gripper workspace boxes of the released code (min xyz, max xyz), per task.
RELEASED_WORKSPACES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "pick_place": ((1.05, 0.4, 0.419), (1.55, 1.1, float("inf"))),
    "push": ((1.05, 0.4, 0.4), (1.55, 1.11, float("inf"))),
    "slide": ((0.7, 0.3, 0.4), (1.95, 1.2, float("inf"))),
    # No released code for the Franka task: no workspace mask.
    "franka_pick_place": ((-float("inf"),) * 3, (float("inf"),) * 3),
}
# Paper defaults per task: (k, temperature); the released code's k per task.
PAPER_PARAMETERS = {
    "pick_place": (100.0, 0.01),
    "push": (100.0, 0.01),
    "slide": (100.0, 5.0),
    "franka_pick_place": (100.0, 0.01),  # the Sim2Real policy: PickAndPlace's values
}
RELEASED_K = {"pick_place": 0.1, "push": 0.1, "slide": 0.05, "franka_pick_place": 0.1}
RELEASED_MIN_EPISODES_FOR_WEIGHTS = 256


class CEBPSampler(EpisodePrioritySampler):
    """Draws episodes by their contact energy: touch on both fingers times object displacement.

    ``form="paper"`` follows the paper's equations: per step
    ``c(t) = sum_{i<=t} (f_l + f_r)(i) * ||d(i) - d(i-1)||``, smoothed to
    ``k / (1 + exp(-temperature * c(t)))``, episode priority the sum over ``t``,
    IS weights ``(N p(e))^-beta`` divided by the batch maximum.

    ``form="released"`` follows the published code: a 3-vector
    ``E(t) = cumsum(displacement * (f_l + f_r))`` zeroed while the gripper is
    outside the task's workspace box, ``x(t) = sum(E(t)) * ||displacement||``,
    the centred sigmoid ``100 / (1 + exp(-k x)) - 50``, priority
    ``sum_t |s(t)| + eps``, IS weights with beta 1, all ones while fewer than
    256 episodes are stored. ``scale``/``temperature`` are ignored there; ``k``
    comes from ``released_k`` (the code's per-task value by default).

    Touch is only used here, to prioritise replay: the policy never sees it.

    Args:
        task: ``"pick_place"``, ``"push"``, ``"slide"`` or ``"franka_pick_place"``;
            selects the documented defaults (paper: k=100, T=0.01, or T=5 for slide;
            released: its k and workspace box; the Franka task takes PickAndPlace's
            values and no workspace mask).
        form: ``"paper"`` (default) or ``"released"``.
        scale: the sigmoid's ``k`` in the paper form (default per task).
        temperature: the sigmoid's ``T`` in the paper form (default per task).
        beta: IS exponent in the paper form (default 1.0, the released effective value).
        released_k: the released form's sigmoid slope (default per task).
        touch_key, position_key, next_position_key, next_observation_key: where
            touch ``[T, 2]``, the object position before each step and after it
            ``[T, 3]``, and the next observation (gripper xyz in ``[..., :3]``) live.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
        >>> from torchrl_cebp.samplers import CEBPSampler
        >>> T = 50
        >>> episodes = TensorDict({
        ...     "achieved_goal": torch.zeros(4, T, 3),
        ...     "next": {"achieved_goal": torch.rand(4, T, 3), "touch": torch.rand(4, T, 2),
        ...              "observation": torch.rand(4, T, 25)}}, [4, T])
        >>> rb = TensorDictReplayBuffer(storage=LazyTensorStorage(100 * T, ndim=2),
        ...                             sampler=CEBPSampler("push"), batch_size=8, dim_extend=0)
        >>> _ = rb.extend(episodes)
        >>> batch = rb.sample()
        >>> batch["priority_weight"].shape
        torch.Size([8])
    """

    def __init__(
        self,
        task: str = "pick_place",
        *,
        form: Literal["paper", "released"] = "paper",
        scale: float | None = None,
        temperature: float | None = None,
        beta: float = 1.0,
        released_k: float | None = None,
        touch_key: NestedKey = ("next", "touch"),
        position_key: NestedKey = "achieved_goal",
        next_position_key: NestedKey = ("next", "achieved_goal"),
        next_observation_key: NestedKey = ("next", "observation"),
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__(generator)
        if task not in PAPER_PARAMETERS:
            raise ValueError(f"unknown task {task!r}; valid tasks: {sorted(PAPER_PARAMETERS)}")
        if form not in ("paper", "released"):
            raise ValueError(f"unknown CEBP form {form!r}; valid forms: ['paper', 'released']")
        default_scale, default_temperature = PAPER_PARAMETERS[task]
        self.task = task
        self.form = form
        self.scale = default_scale if scale is None else float(scale)
        self.temperature = default_temperature if temperature is None else float(temperature)
        self.beta = float(beta)
        self.released_k = RELEASED_K[task] if released_k is None else float(released_k)
        self.touch_key = touch_key
        self.position_key = position_key
        self.next_position_key = next_position_key
        self.next_observation_key = next_observation_key
        low, high = RELEASED_WORKSPACES[task]
        self._workspace = (torch.tensor(low, dtype=torch.float64), torch.tensor(high, dtype=torch.float64))

    def episode_priority(self, episodes: TensorDictBase) -> torch.Tensor:
        touch = require_key(episodes, self.touch_key, (2,)).double().sum(-1)
        positions = episode_positions(episodes, self.position_key, self.next_position_key)
        displacement = positions[:, 1:] - positions[:, :-1]
        distance = torch.linalg.vector_norm(displacement, dim=-1)
        if self.form == "paper":
            energy = torch.cumsum(touch * distance, dim=1)
            smoothed = self.scale * torch.sigmoid(self.temperature * energy)
            return smoothed.sum(1)
        gripper = require_key(episodes, self.next_observation_key, (None,))[..., :3].double()
        low, high = self._workspace
        inside = ((gripper >= low) & (gripper <= high)).all(-1, keepdim=True)
        energy = torch.cumsum(displacement * touch.unsqueeze(-1), dim=1) * inside
        x = energy.sum(-1) * distance
        centred = 100.0 * torch.sigmoid(self.released_k * x) - 50.0
        return centred.abs().sum(1) + FLOAT32_EPS

    def importance_weights(self, probabilities: torch.Tensor, n_episodes: int) -> torch.Tensor:
        if self.form == "released":
            if n_episodes < RELEASED_MIN_EPISODES_FOR_WEIGHTS:
                return torch.ones_like(probabilities)
            beta = 1.0
        else:
            beta = self.beta
        weights = (n_episodes * probabilities) ** (-beta)
        return weights / weights.max()

    def __repr__(self) -> str:
        if self.form == "paper":
            detail = f"scale={self.scale}, temperature={self.temperature}, beta={self.beta}"
        else:
            detail = f"k={self.released_k}"
        return f"CEBPSampler(task={self.task!r}, form='{self.form}', {detail}, n_episodes={self.n_episodes})"
