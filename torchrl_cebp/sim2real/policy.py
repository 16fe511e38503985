"""The policies the Sim2Real loop runs: the shipped trained one, and a scripted pick-and-place.

Other trained policies load with ``torchrl_cebp.training.load_policy``.
"""

from __future__ import annotations


import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_cebp.agents.shipped import SHIPPED_AGENTS
from torchrl_cebp.envs.layout import FETCH_OBSERVATION as OBS

__all__ = ["SHIPPED_POLICY", "ScriptedPickPlace"]

# The Franka pick-and-place policy trained with CEBP (docs/results/sim2real/).
SHIPPED_POLICY = SHIPPED_AGENTS["franka_pick_place"]


class ScriptedPickPlace(TensorDictModuleBase):
    """A hand-written pick-and-place from the Fetch observation: hover, descend, close, carry to the goal.

    Writes a zero action while the observation holds NaN (cube not perceived), which the loop does not execute anyway.

    Args:
        max_step (float, optional): the displacement an action of 1 commands (the env's action scale).
            Defaults to ``0.05``.
        hover (float, optional): height above the cube to line up at before descending. Defaults to ``0.06``.
        tolerance (float, optional): how close the grip must be to the cube to close on it. Defaults to ``0.012``.
        closed_width (float, optional): finger-pad distance below which the cube counts as grasped.
            Defaults to ``0.056``.

    Example:
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.envs import FETCH_OBSERVATION as OBS
        >>> obs = torch.zeros(OBS.size); obs[OBS.object_position] = torch.tensor([0.1, 0.0, 0.0])
        >>> obs[OBS.finger_positions] = 0.04
        >>> td = ScriptedPickPlace()(TensorDict(observation=obs, desired_goal=torch.zeros(3)))
        >>> td["action"].tolist()
        [1.0, 0.0, 1.0, 1.0]
    """

    def __init__(self, max_step: float = 0.05, hover: float = 0.06, tolerance: float = 0.012, closed_width: float = 0.056):
        super().__init__()
        self.in_keys, self.out_keys = ["observation", "desired_goal"], ["action"]
        self.max_step, self.hover, self.tolerance, self.closed_width = max_step, hover, tolerance, closed_width

    def _act(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        if not torch.isfinite(obs).all():
            return torch.zeros(4)
        grip, cube, width = obs[OBS.gripper_position], obs[OBS.object_position], OBS.gripper_opening(obs)
        at_cube = torch.linalg.vector_norm(cube - grip) < self.tolerance
        if at_cube and width > self.closed_width:
            target, gripper = grip, -1.0  # closing: stay put until the fingers are on the cube
        elif at_cube:
            target, gripper = goal, -1.0
        elif torch.linalg.vector_norm(cube[:2] - grip[:2]) > self.tolerance / 2:
            target, gripper = cube + torch.tensor([0.0, 0.0, self.hover]), 1.0
        else:
            target, gripper = cube, 1.0
        move = ((target - grip) / self.max_step).clamp(-1.0, 1.0)
        return torch.cat([move, torch.tensor([gripper])])

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Writes ``"action"`` ``[..., 4]`` for every observation and goal of ``tensordict``.

        Args:
            tensordict (TensorDictBase): holds ``"observation"`` and ``"desired_goal"``, any batch size.
        """
        obs, goal = tensordict.get("observation"), tensordict.get("desired_goal")
        actions = [self._act(o, g) for o, g in zip(obs.reshape(-1, obs.shape[-1]), goal.reshape(-1, goal.shape[-1]))]
        tensordict.set("action", torch.stack(actions).reshape(*obs.shape[:-1], 4).to(obs.dtype))
        return tensordict
