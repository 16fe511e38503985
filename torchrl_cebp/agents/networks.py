"""The actor and critic of DDPG+HER: 3 x 256 ReLU MLPs on the normalised observation and goal."""

from __future__ import annotations

from collections.abc import Sequence

from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import MLP, ValueOperator


def make_actor(
    input_dim: int, action_dim: int, hidden: Sequence[int] = (256, 256, 256), *, in_key: str = "agent_input"
) -> TensorDictModule:
    """A deterministic tanh policy reading ``in_key`` and writing ``"action"`` in ``[-1, 1]``.

    Args:
        input_dim (int): the input's size (observation + goal).
        action_dim (int): the action's size.
        hidden (sequence of int, optional): the hidden layers' widths (ReLU). Defaults to ``(256, 256, 256)``.
        in_key (str, optional): the input's key (keyword only). Defaults to ``"agent_input"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> actor = make_actor(28, 4)
        >>> actor(TensorDict({"agent_input": torch.randn(5, 28)}, [5]))["action"].shape
        torch.Size([5, 4])
    """
    net = nn.Sequential(
        MLP(in_features=input_dim, out_features=action_dim, num_cells=list(hidden), activation_class=nn.ReLU),
        nn.Tanh(),
    )
    return TensorDictModule(net, in_keys=[in_key], out_keys=["action"])


def make_critic(
    input_dim: int, action_dim: int, hidden: Sequence[int] = (256, 256, 256), *, in_key: str = "agent_input"
) -> ValueOperator:
    """A Q-network reading ``in_key`` and ``"action"``, writing ``"state_action_value"`` [..., 1].

    Args:
        input_dim (int): the input's size (observation + goal).
        action_dim (int): the action's size.
        hidden (sequence of int, optional): the hidden layers' widths (ReLU). Defaults to ``(256, 256, 256)``.
        in_key (str, optional): the input's key (keyword only). Defaults to ``"agent_input"``.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> critic = make_critic(28, 4)
        >>> td = TensorDict({"agent_input": torch.randn(5, 28), "action": torch.rand(5, 4)}, [5])
        >>> critic(td)["state_action_value"].shape
        torch.Size([5, 1])
    """
    net = MLP(in_features=input_dim + action_dim, out_features=1, num_cells=list(hidden), activation_class=nn.ReLU)
    return ValueOperator(net, in_keys=[in_key, "action"])
