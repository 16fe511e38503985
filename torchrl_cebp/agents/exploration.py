"""HER's exploration: epsilon-random actions, otherwise Gaussian noise on the policy's."""

from __future__ import annotations

import numpy as np
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

    Draws from ``generator`` (torch's global one when ``None``). :meth:`reseed` restarts the
    stream reproducibly wherever the module runs: the seed is a buffer, so it travels with the
    policy's weights into a collector's worker processes, and the first call after it changes
    restarts the generator from the seed and that call's observations. Each worker of a
    multi-process collector (its envs seeded apart) thereby gets its own stream.

    Args:
        random_eps (float, optional): probability of a uniform random action. Defaults to ``0.3``.
        noise_std (float, optional): standard deviation of the Gaussian noise. Defaults to ``0.2``.
        low (float, optional): the action's lower bound. Defaults to ``-1.0``.
        high (float, optional): the action's upper bound. Defaults to ``1.0``.
        action_key (str, optional): the action read and overwritten. Defaults to ``"action"``.
        observation_key (str, optional): the observation that tells workers apart after a
            :meth:`reseed`. Defaults to ``"observation"``.
        generator (torch.Generator, optional): the noise's generator; ``None`` draws from torch's global
            one until the first :meth:`reseed`. Defaults to ``None``.

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
        >>> td["observation"] = torch.ones(1000, 25)
        >>> explore.reseed(7)
        >>> first = explore(td.clone())["action"]
        >>> explore.reseed(7)
        >>> bool((explore(td.clone())["action"] == first).all())
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
        observation_key: str = "observation",
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.in_keys = [action_key]
        self.out_keys = [action_key]
        self.random_eps = random_eps
        self.noise_std = noise_std
        self.low = low
        self.high = high
        self.observation_key = observation_key
        self.generator = generator
        # (seed, how many reseeds so far): a buffer, so that a weight sync carries a reseed to the workers.
        self.register_buffer("noise_seed", torch.zeros(2, dtype=torch.int64))
        self._applied_reseeds = 0

    def reseed(self, seed: int) -> None:
        """Restarts the noise stream from ``seed`` at the next call (here, or in a worker after a weight sync).

        Args:
            seed (int): a non-negative seed.

        Raises:
            ValueError: a negative seed.
        """
        if seed < 0:
            raise ValueError(f"seed must be non-negative, got {seed}")
        self.noise_seed[0] = seed
        self.noise_seed[1] += 1

    def _restart_if_reseeded(self, td: TensorDictBase) -> None:
        seed, reseeds = self.noise_seed.tolist()
        if reseeds == self._applied_reseeds:
            return
        self._applied_reseeds = reseeds
        observation = td.get(self.observation_key, None)
        # The observations tell workers apart: they run the same policy copy on envs seeded apart.
        mixed = [seed] if observation is None else [seed, *np.frombuffer(observation.float().numpy().tobytes()[:4096], np.uint32)]
        if self.generator is None:  # from now on, off torch's global stream
            self.generator = torch.Generator(device=td.device or "cpu")
        self.generator.manual_seed(int(np.random.SeedSequence(mixed).generate_state(1)[0]))

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        """Perturbs ``td``'s action in place under the random exploration type; otherwise returns ``td`` unchanged.

        Args:
            td (TensorDictBase): holds the policy's action.
        """
        if exploration_type() not in (ExplorationType.RANDOM, None):
            return td
        self._restart_if_reseeded(td)
        action = td.get(self.in_keys[0])
        noise = torch.randn(action.shape, generator=self.generator, device=action.device, dtype=action.dtype)
        noisy = (action + self.noise_std * noise).clamp(self.low, self.high)
        uniform = torch.empty_like(action).uniform_(self.low, self.high, generator=self.generator)
        replace = torch.rand(action.shape[:-1] + (1,), generator=self.generator, device=action.device) < self.random_eps
        td.set(self.out_keys[0], torch.where(replace, uniform, noisy))
        return td
