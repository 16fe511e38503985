"""Exploration episodes from a copy of the policy, collected here or in a worker process.

The trainer sends the policy's weights with each request, so the collecting copy acts
exactly as the trained policy did when the request was made. A :class:`RolloutWorker`
runs the simulation in its own process, so that it overlaps the updates on another core.
"""

from __future__ import annotations

import multiprocessing as mp
import pickle
from collections.abc import Callable
from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictSequential
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from torchrl_cebp.agents import HERExploration, ObsGoalNormalizer, make_actor


@dataclass(frozen=True)
class Seeds:
    """The streams a collection restarts from: the simulations' and the exploration noise's."""

    env: int
    exploration: int


def make_policy(
    obs_dim: int, goal_dim: int, action_dim: int, hidden: list[int], **exploration
) -> tuple[TensorDictSequential, TensorDictSequential]:
    """The deterministic policy (normaliser, actor) and the same modules followed by :class:`HERExploration`.

    ``exploration`` goes to :class:`HERExploration` (``random_eps``, ``noise_std``, ``generator``).

    Examples:
        >>> policy, explore = make_policy(25, 3, 4, [32])
        >>> explore[0] is policy  # one set of weights: the exploration wraps the deterministic policy
        True
    """
    actor = make_actor(obs_dim + goal_dim, action_dim, hidden)
    policy = TensorDictSequential(ObsGoalNormalizer(obs_dim, goal_dim), actor)
    return policy, TensorDictSequential(policy, HERExploration(**exploration))


class Rollouts:
    """Whole episodes ``[n_envs, T]`` from ``env`` under ``policy`` (an exploration policy, see :func:`make_policy`).

    :meth:`submit` loads the weights and, with ``seeds``, restarts the env's and the
    exploration's random streams; :meth:`result` collects. Collecting in :meth:`result`
    keeps the order of work of the single-process trainer.

    Example:
        >>> from torchrl_cebp.envs import make_env
        >>> _, explore = make_policy(25, 3, 4, [32], generator=torch.Generator())
        >>> rollouts = Rollouts(make_env("push", num_envs=2), explore, 50, drop_keys=["agent_input"])
        >>> rollouts.submit(explore.state_dict(), Seeds(env=0, exploration=1))
        >>> rollouts.result().shape
        torch.Size([2, 50])
    """

    def __init__(self, env: EnvBase, policy: TensorDictSequential, episode_steps: int, drop_keys: list[str]) -> None:
        self.env = env
        self.policy = policy
        self.exploration = next(m for m in policy.modules() if isinstance(m, HERExploration))
        self.episode_steps = episode_steps
        self.drop_keys = drop_keys
        self._pending = False

    def submit(self, weights: dict[str, torch.Tensor], seeds: Seeds | None = None) -> None:
        self.policy.load_state_dict(weights)
        if seeds is not None:
            self.env.set_seed(seeds.env)
            self.exploration.generator.manual_seed(seeds.exploration)
        self._pending = True

    def busy(self) -> bool:
        """Whether a submitted collection is running in the background: never here (it runs in :meth:`result`)."""
        return False

    @torch.no_grad()
    def result(self) -> TensorDictBase:
        if not self._pending:
            raise RuntimeError("result() without a submit()")
        self._pending = False
        with set_exploration_type(ExplorationType.RANDOM):
            episodes = self.env.rollout(self.episode_steps, self.policy, break_when_any_done=False)
        return episodes.exclude(*self.drop_keys)

    def close(self) -> None:
        self.env.close()


def _serve(conn, make_rollouts: Callable[[], Rollouts]) -> None:
    # One thread: the other core runs the updates.
    torch.set_num_threads(1)
    rollouts = make_rollouts()
    conn.send_bytes(b"ready")
    try:
        # An empty request, or the trainer's end of the pipe closing (it failed), ends the worker.
        while (request := conn.recv_bytes()) != b"":
            rollouts.submit(*pickle.loads(request))
            conn.send_bytes(pickle.dumps(rollouts.result()))
    except EOFError:
        pass
    finally:
        rollouts.close()


class RolloutWorker:
    """A :class:`Rollouts` from ``make_rollouts`` (picklable) in a spawned process: ``submit`` returns at once.

    Weights and episodes cross the pipe as plain pickles (copies, no shared memory),
    so the worker's copy of the policy changes only when asked.

    Its use (and a test of it) is in the trainer with ``overlap_collection=true``; the spawned
    process must be able to import ``make_rollouts``, so it cannot be defined in an example here.
    """

    def __init__(self, make_rollouts: Callable[[], Rollouts]) -> None:
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        # A daemon, so that a trainer that fails does not wait for it (it cannot host a ParallelEnv then).
        self._process = ctx.Process(target=_serve, args=(child, make_rollouts), name="rollouts", daemon=True)
        self._process.start()
        child.close()
        self._collecting = False
        # Waits for the worker's envs, so that its start-up (seconds) is not counted as collection.
        if self._conn.recv_bytes() != b"ready":
            raise RuntimeError("the rollout worker failed to start")

    def submit(self, weights: dict[str, torch.Tensor], seeds: Seeds | None = None) -> None:
        self._conn.send_bytes(pickle.dumps((weights, seeds)))
        self._collecting = True

    def busy(self) -> bool:
        """Whether the worker is still collecting the submitted episodes (it holds a core meanwhile)."""
        self._collecting = self._collecting and not self._conn.poll()
        return self._collecting

    def result(self) -> TensorDictBase:
        self._collecting = False
        return pickle.loads(self._conn.recv_bytes())

    def close(self) -> None:
        self._conn.send_bytes(b"")
        self._process.join()
