from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from tensordict import TensorDict

from torchrl_cebp.training.config import CONFIG_DIR

T = 50
# The released code's gripper box for Push, as the env config states it.
PUSH_WORKSPACE = tuple(map(tuple, OmegaConf.load(CONFIG_DIR / "env" / "push.yaml").gripper_workspace))


def sparse_reward(achieved_goal: torch.Tensor, desired_goal: torch.Tensor) -> torch.Tensor:
    return -(torch.linalg.vector_norm(achieved_goal - desired_goal, dim=-1, keepdim=True) > 0.05).float()


def restore(saved, restored, how: str, tmp_path: Path) -> None:
    """Restores buffer (or sampler) ``saved`` into ``restored``: through files (``how="dumps"``) or a state dict."""
    if how == "dumps":
        saved.dumps(tmp_path)
        restored.loads(tmp_path)
    else:
        restored.load_state_dict(saved.state_dict())


def make_episodes(
    n: int,
    length: int = T,
    *,
    touch: torch.Tensor | None = None,
    positions: torch.Tensor | None = None,
    gripper: torch.Tensor | None = None,
    seed: int = 0,
) -> TensorDict:
    """Episodes in the env's layout. ``positions`` is the object path ``[n, T + 1, 3]``."""
    g = torch.Generator().manual_seed(seed)
    if positions is None:
        positions = torch.rand(n, length + 1, 3, generator=g)
    if touch is None:
        touch = torch.rand(n, length, 2, generator=g)
    observation = torch.rand(n, length + 1, 25, generator=g)
    if gripper is not None:
        observation[..., :3] = gripper
    goal = torch.rand(n, 1, 3, generator=g).expand(n, length + 1, 3)

    def state(sl):
        return {
            "observation": observation[:, sl],
            "achieved_goal": positions[:, sl],
            "desired_goal": goal[:, sl],
            "touch": torch.cat([torch.zeros(n, 1, 2), touch], 1)[:, sl],
        }

    now, after = slice(0, length), slice(1, length + 1)
    nxt = state(after)
    nxt["reward"] = sparse_reward(positions[:, after], goal[:, after])
    nxt["done"] = torch.zeros(n, length, 1, dtype=torch.bool)
    nxt["done"][:, -1] = True
    return TensorDict({**state(now), "action": torch.rand(n, length, 4, generator=g), "next": nxt}, [n, length]).clone()


@pytest.fixture
def episodes():
    return make_episodes
