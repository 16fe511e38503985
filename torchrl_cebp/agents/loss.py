"""DDPG loss with HER's clipped critic target and action penalty."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torchrl.objectives import DDPGLoss
from torchrl.objectives.value import TD0Estimator


class ClippedTD0Estimator(TD0Estimator):
    """One-step TD target ``r + gamma * Q'(s', pi'(s'))`` clipped to ``[low, high]``.

    With rewards in ``{-1, 0}`` every return lies in ``[-1/(1-gamma), 0]``; clipping the
    bootstrapped target to that range keeps early, wild target estimates from feeding back.

    Args:
        low (float): the target's lower bound (keyword only).
        high (float): the target's upper bound (keyword only).
        **kwargs: passed to :class:`~torchrl.objectives.value.TD0Estimator` (``gamma``, ``value_network``, ...).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl.modules import ValueOperator
        >>> value = ValueOperator(torch.nn.Linear(3, 1), in_keys=["observation"])
        >>> est = ClippedTD0Estimator(gamma=0.98, value_network=value, low=-50.0, high=0.0)
        >>> td = TensorDict({"next": {"observation": torch.randn(4, 3), "reward": torch.full((4, 1), 7.0),
        ...     "done": torch.zeros(4, 1, dtype=torch.bool), "terminated": torch.zeros(4, 1, dtype=torch.bool)}}, [4])
        >>> est.value_estimate(td).max().item()
        0.0
    """

    def __init__(self, *, low: float, high: float, **kwargs) -> None:
        super().__init__(**kwargs)
        self.low = low
        self.high = high

    def value_estimate(self, tensordict: TensorDictBase, *args, **kwargs) -> torch.Tensor:
        """:class:`~torchrl.objectives.value.TD0Estimator`'s target, clipped to ``[low, high]``.

        Args:
            tensordict (TensorDictBase): the batch, with its ``"next"`` entries.
            *args: passed to ``TD0Estimator.value_estimate``.
            **kwargs: passed to ``TD0Estimator.value_estimate``.
        """
        return super().value_estimate(tensordict, *args, **kwargs).clamp(self.low, self.high)


class HERDDPGLoss(DDPGLoss):
    """TorchRL's :class:`~torchrl.objectives.DDPGLoss` set up as baselines' DDPG+HER.

    - target actor and critic (update them with ``SoftUpdate(loss, tau=0.05)``);
    - critic target clipped to ``[-1/(1-gamma), 0]`` (:class:`ClippedTD0Estimator`);
    - importance-sampling weights (``"priority_weight"``, when the batch has them) weight
      the critic's squared TD errors as baselines does, ``mean(w * delta^2)`` (the CEBP
      Initial commit's and EBP's PER's ``ddpg.py``); DDPGLoss's own weighted mean divides by
      ``sum(w)`` instead, which puts the critic's gradient back at the unweighted scale;
    - the actor loss is ``-mean Q(s, pi(s)) + action_l2 * mean(pi(s)^2)``, unweighted:
      the prioritised HER implementations (PER, CEBP) apply IS weights to the critic only.

    ``"td_error"`` is written into the input batch for prioritised samplers as ``|Q - target|``,
    baselines' PER priority before ``eps`` and ``alpha`` (TorchRL's DDPGLoss writes the square).

    Args:
        actor_network (TensorDictModule): the policy, e.g. :func:`~torchrl_cebp.agents.make_actor`.
        value_network (TensorDictModule): the Q-network, e.g. :func:`~torchrl_cebp.agents.make_critic`.
        gamma (float): the discount (keyword only); the critic target is clipped to ``[-1/(1-gamma), 0]``.
        action_l2 (float, optional): weight of the actor's action penalty (keyword only). Defaults to ``1.0``.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_cebp.agents import make_actor, make_critic
        >>> loss = HERDDPGLoss(make_actor(28, 4), make_critic(28, 4), gamma=0.98)
        >>> def part(): return {"agent_input": torch.randn(8, 28)}
        >>> batch = TensorDict({**part(), "action": torch.rand(8, 4), "next": {**part(),
        ...     "reward": -torch.ones(8, 1), "done": torch.zeros(8, 1, dtype=torch.bool),
        ...     "terminated": torch.zeros(8, 1, dtype=torch.bool)}}, [8])
        >>> out = loss(batch)
        >>> sorted(k for k in out.keys() if k.startswith("loss_"))
        ['loss_actor', 'loss_value']
        >>> bool((out["target_value"] <= 0).all() and (out["target_value"] >= -50).all())
        True
    """

    def __init__(
        self,
        actor_network: TensorDictModule,
        value_network: TensorDictModule,
        *,
        gamma: float,
        action_l2: float = 1.0,
    ) -> None:
        super().__init__(actor_network, value_network, delay_actor=True, delay_value=True)
        self.action_l2 = action_l2
        self.make_value_estimator(
            ClippedTD0Estimator(
                gamma=gamma, value_network=self.actor_critic, low=-1.0 / (1.0 - gamma), high=0.0
            )
        )
        # An estimator instance keeps its own default keys (its value is "state_value"); give it the loss's.
        self.value_estimator.set_keys(
            value=self.tensor_keys.state_action_value,
            reward=self.tensor_keys.reward,
            done=self.tensor_keys.done,
            terminated=self.tensor_keys.terminated,
        )

    def loss_value(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, dict]:
        """The critic's loss, ``mean(w * delta^2)``; writes ``|delta|`` into ``tensordict`` as the priority.

        Args:
            tensordict (TensorDictBase): the batch, with the normalised inputs at root and ``"next"``.

        Returns:
            the loss and DDPGLoss's metadata, with ``"td_error"``.
        """
        loss, metadata = super().loss_value(tensordict)
        weights = tensordict.get(self.tensor_keys.priority_weight, None)
        if weights is not None and self.use_prioritized_weights in (True, "auto") and self.reduction == "mean":
            # DDPGLoss's weighted mean is sum(w l) / sum(w); times mean(w) it is baselines' mean(w l). With CEBP's
            # max-normalised weights mean(w) falls to ~0.02 once they turn on, and so does the critic's gradient.
            loss = loss * weights.mean()
        # TorchRL's DDPGLoss writes the squared TD error: as a PER priority that would double alpha.
        abs_error = (metadata["pred_value"] - metadata["target_value"]).abs().detach()
        tensordict.set(self.tensor_keys.priority, abs_error, inplace=True)
        return loss, {**metadata, "td_error": abs_error}

    def loss_actor(self, tensordict: TensorDictBase) -> tuple[torch.Tensor, dict]:
        """The actor's loss, ``-mean Q(s, pi(s)) + action_l2 * mean(pi(s)^2)``, unweighted.

        Args:
            tensordict (TensorDictBase): the batch.

        Returns:
            the loss and ``{"action_l2": mean(pi(s)^2)}``.
        """
        td = tensordict.select(*self.actor_in_keys, *self.value_exclusive_keys, strict=False).detach()
        with self.actor_network_params.to_module(self.actor_network, preserve_module_state=False):
            td = self.actor_network(td)
        with self.value_network_params.detach().to_module(self.value_network, preserve_module_state=False):
            td = self.value_network(td)
        action = td.get(self.actor_network.out_keys[0])
        action_penalty = action.square().mean()
        q = td.get(self.tensor_keys.state_action_value)
        loss = -q.mean() + self.action_l2 * action_penalty
        return loss, {"action_l2": action_penalty.detach()}
