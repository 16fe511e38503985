"""Exploration episodes through TorchRL collectors: in this process, or in env processes that overlap the updates.

:func:`make_collector` builds a :class:`~torchrl.collectors.Collector` (in this process) or a
:class:`~torchrl.collectors.MultiSyncCollector` (``processes`` env processes, each with its share of
the envs). Every batch is whole episodes ``[n_envs, T]``: the collector resets its envs at each
batch. :class:`EpisodeBatches` asks the collector for one batch at a time, so a batch is only ever
collected when the trainer asks, with the weights and seeds it set just before: that is what lets a
resumed run repeat an uninterrupted one. Asked with ``background=True`` it collects in a thread
while the caller goes on (the env processes do the work; the thread only waits for them).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictSequential
from torchrl.collectors import BaseCollector, Collector, MultiSyncCollector
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType

from torchrl_cebp.agents import HERExploration, ObsGoalNormalizer, make_actor

# What a collector adds to every batch that the replay does not store.
COLLECTOR_KEYS = ("collector", "agent_input")


def make_policy(
    obs_dim: int, goal_dim: int, action_dim: int, hidden: list[int], **exploration
) -> tuple[TensorDictSequential, TensorDictSequential]:
    """The deterministic policy (normaliser, actor) and the same modules followed by :class:`HERExploration`.

    Args:
        obs_dim (int): the observation size.
        goal_dim (int): the goal size.
        action_dim (int): the action size.
        hidden (list of int): the actor's hidden layers' widths.
        **exploration: passed to :class:`~torchrl_cebp.agents.HERExploration` (``random_eps``,
            ``noise_std``, ``generator``).

    Returns:
        ``(policy, exploration_policy)``, sharing one set of weights.

    Examples:
        >>> policy, explore = make_policy(25, 3, 4, [32])
        >>> explore[0] is policy  # one set of weights: the exploration wraps the deterministic policy
        True
    """
    actor = make_actor(obs_dim + goal_dim, action_dim, hidden)
    policy = TensorDictSequential(ObsGoalNormalizer(obs_dim, goal_dim), actor)
    return policy, TensorDictSequential(policy, HERExploration(**exploration))


def make_collector(
    make_env: Callable[[int], EnvBase],
    policy: TensorDictSequential,
    *,
    n_envs: int,
    episode_steps: int,
    processes: int = 0,
) -> BaseCollector:
    """A TorchRL collector of whole episodes: ``n_envs`` envs of ``episode_steps`` steps per batch.

    ``processes=0`` steps the envs in this process; ``processes=n`` gives each of ``n`` env processes
    ``n_envs / n`` of them (a :class:`~torchrl.collectors.MultiSyncCollector`, whose weights follow
    the policy at :meth:`~torchrl.collectors.BaseCollector.update_policy_weights_`). Give it a copy of
    the trained policy when the training changes it while a batch is collected (:class:`EpisodeBatches`).

    Args:
        make_env (callable): ``make_env(k)`` builds a batched env of ``k`` simulations (picklable with
            ``processes`` > 0).
        policy (TensorDictSequential): the exploration policy.
        n_envs (int): episodes per batch (keyword only).
        episode_steps (int): steps per episode (keyword only).
        processes (int, optional): env processes; ``0`` steps the envs in this process (keyword only).
            Defaults to ``0``.

    Raises:
        ValueError: ``processes`` does not divide ``n_envs``.

    Example:
        >>> import functools
        >>> from torchrl_cebp.envs import make_env
        >>> _, explore = make_policy(25, 3, 4, [32])
        >>> collector = make_collector(lambda k: make_env("push", num_envs=k), explore, n_envs=2, episode_steps=50)
        >>> next(iter(collector)).shape
        torch.Size([2, 50])
        >>> collector.shutdown()
    """
    common = dict(
        frames_per_batch=n_envs * episode_steps,
        total_frames=-1,
        reset_at_each_iter=True,
        exploration_type=ExplorationType.RANDOM,
        auto_register_policy_transforms=False,  # the policy needs no env transform
    )
    if processes == 0:
        return Collector(make_env(n_envs), policy, **common)
    if n_envs % processes:
        raise ValueError(f"n_envs={n_envs} episodes per batch cannot be split evenly over processes={processes}")
    env_fn = _EnvFactory(make_env, n_envs // processes)
    return MultiSyncCollector([env_fn] * processes, policy, cat_results=0, use_buffers=True, **common)


class _EnvFactory:
    """``make_env(n)`` as a picklable zero-argument callable, for the env processes."""

    def __init__(self, make_env: Callable[[int], EnvBase], n_envs: int) -> None:
        self.make_env = make_env
        self.n_envs = n_envs

    def __call__(self) -> EnvBase:
        torch.set_num_threads(1)  # a simulation process: its one core stays its own
        return self.make_env(self.n_envs)


class EpisodeBatches:
    """One batch of episodes per :meth:`request`, from ``collector``, with ``policy``'s weights and seeds of that moment.

    ``collector`` runs its own copy of ``policy`` (an exploration policy, see :func:`make_policy`):
    the trainer's updates change ``policy`` while a background batch is collected, and the copy
    only changes at :meth:`request`, which copies ``policy``'s weights into it and, with ``seed``,
    restarts the envs' and the exploration's streams. :meth:`result` returns the batch, without
    the collector's bookkeeping keys. With ``background=True`` the batch is collected in a thread
    meanwhile; :meth:`busy` says whether it still is.

    Args:
        collector (BaseCollector): a collector of :func:`make_collector`, with its own copy of ``policy``.
        policy (TensorDictSequential): the trained exploration policy, holding a
            :class:`~torchrl_cebp.agents.HERExploration`.

    Example:
        >>> import copy
        >>> from torchrl_cebp.envs import make_env
        >>> _, explore = make_policy(25, 3, 4, [32])
        >>> collector = make_collector(lambda k: make_env("push", num_envs=k), copy.deepcopy(explore),
        ...                            n_envs=2, episode_steps=50)
        >>> batches = EpisodeBatches(collector, explore)
        >>> batches.request(seed=0)
        >>> batches.result().shape
        torch.Size([2, 50])
        >>> batches.close()
    """

    def __init__(self, collector: BaseCollector, policy: TensorDictSequential) -> None:
        self.collector = collector
        self.policy = policy
        self.exploration = next(m for m in policy.modules() if isinstance(m, HERExploration))
        self._iterator = iter(collector)
        self._pending: Future | None = None

    def request(self, seed: int | None = None, *, background: bool = False) -> None:
        """Starts collecting one batch with ``policy``'s current weights.

        Args:
            seed (int, optional): restarts the envs' and the exploration's streams; ``None`` goes on with them.
                Defaults to ``None``.
            background (bool, optional): collect in a thread and return at once (keyword only).
                Defaults to ``False``.

        Raises:
            RuntimeError: the previous batch's :meth:`result` has not been taken.
        """
        if self._pending is not None:
            raise RuntimeError("request() before the previous batch's result()")
        if seed is not None:
            self.exploration.reseed(seed)  # a buffer of the policy: the weight copy below carries it
            self.collector.set_seed(seed)
        self.collector.update_policy_weights_(TensorDict.from_module(self.policy))
        self._pending = Future()
        if background:
            threading.Thread(target=self._collect, args=(self._pending,), name="episode-batches", daemon=True).start()
        else:
            self._collect(self._pending)

    def _collect(self, batch: Future) -> None:
        try:
            with torch.no_grad():
                batch.set_result(next(self._iterator).exclude(*COLLECTOR_KEYS))
        except BaseException as err:  # re-raised in the trainer's thread by result()
            batch.set_exception(err)

    def busy(self) -> bool:
        """Whether a background batch is still being collected (its env process holds a core meanwhile)."""
        return self._pending is not None and not self._pending.done()

    def result(self) -> TensorDictBase:
        """The requested batch ``[n_envs, T]``, waiting for it if it is collected in the background.

        Raises:
            RuntimeError: nothing was requested; or the error the collection raised.
        """
        if self._pending is None:
            raise RuntimeError("result() without a request()")
        pending, self._pending = self._pending, None
        return pending.result()

    def close(self) -> None:
        """Waits for a background batch, then shuts the collector down."""
        if self._pending is not None:
            self._pending.exception()  # let a background batch finish before the processes go
        self.collector.shutdown()
