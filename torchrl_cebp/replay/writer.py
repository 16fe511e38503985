"""A TorchRL writer that assembles whole episodes from the frames a collector yields."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase, pad
from tensordict.utils import NestedKey
from torchrl.data import TensorDictRoundRobinWriter

from torchrl_cebp import _upstream
from torchrl_cebp.replay.episodes import require_time_at

PARTIAL_EPISODES_FILE = "partial_episodes.pt"


class EpisodeWriter(TensorDictRoundRobinWriter):
    """Writes the episodes a batch of frames completes as ``[episode, t]`` rows; the rest waits for its end.

    A collector yields frames, not episodes: flat ``[frames]`` from one env, ``[envs, frames]``
    from a batched env, ``[nodes, envs, T]`` stacked, and an episode may run over several batches
    or end early. Every leading dimension is an env lane and the last one is time (TorchRL's
    collector and ``rollout`` layout, which names it ``"time"``). Each lane is cut after each
    ``end_key`` flag; an episode that ends is padded to ``max_episode_steps`` (the storage's row
    length) and written round-robin, and the frames after a lane's last end wait for the next
    batch. Frames are matched to the episode they continue by ``traj_key`` (the collector's
    trajectory ids, so batches of different workers mix safely), else by their lane; they continue
    it only if their first state is its last next-state (TorchRL's ``step_mdp``), so an episode cut
    by a reset (a new ``rollout``, a collector's ``reset_at_each_iter``) is dropped, never merged.

    ``rb.extend(batch)`` returns where each frame of ``batch`` was stored: its flat transition
    index ``row * max_episode_steps + step`` (how TorchRL's prioritized sampler numbers the
    transitions of an ``ndim=2`` storage), -1 while its episode has not ended. The buffer must
    extend along dimension 0 (``dim_extend=0``): the writer refuses a batch whose ``"time"``
    dimension is not its last. ``rb.empty()`` drops the waiting frames too.

    Args:
        max_episode_steps (int): the storage's row length, the longest episode (``env.max_episode_steps``).
        end_key (NestedKey, optional): the flag that ends an episode. Defaults to ``("next", "done")``.
        traj_key (NestedKey, optional): the trajectory id of each frame, if the batch has it.
            Defaults to ``("collector", "traj_ids")``.
        compilable (bool, optional): whether the writer is compilable (TorchRL's writer argument); if ``True``,
            the writer cannot be shared between processes. Defaults to ``False``.

    Examples:
        >>> from torchrl.collectors import Collector
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.envs import make_env
        >>> from torchrl_cebp.replay import EpisodeStorage, EpisodeWriter
        >>> env = make_env("push", seed=0, num_envs=2)
        >>> collector = Collector(env, None, frames_per_batch=2 * 30, total_frames=-1,
        ...                       auto_register_policy_transforms=False)
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(100 * 50), writer=EpisodeWriter(50),
        ...                             dim_extend=0, batch_size=16)
        >>> batches = iter(collector)
        >>> _ = rb.extend(next(batches))  # [2, 30]: two episodes begun, none ended
        >>> len(rb)
        0
        >>> _ = rb.extend(next(batches))  # their last 20 steps, and 10 of the next two
        >>> rb.storage.shape
        torch.Size([2, 50])
        >>> collector.shutdown()
    """

    def __init__(
        self,
        max_episode_steps: int,
        *,
        end_key: NestedKey = ("next", "done"),
        traj_key: NestedKey = ("collector", "traj_ids"),
        compilable: bool = False,
    ) -> None:
        super().__init__(compilable=compilable)
        self.max_episode_steps = int(max_episode_steps)
        self.end_key = end_key
        self.traj_key = traj_key
        # The frames of each episode that has not ended yet, by trajectory id (or lane).
        self._partial: dict[int, TensorDictBase] = {}

    def add(self, data: TensorDictBase) -> torch.Tensor:
        return self.extend(data.unsqueeze(0)).squeeze(0)

    def extend(self, data: TensorDictBase) -> torch.Tensor:
        # A refused batch changes nothing: neither the waiting frames nor the next row (the storage refuses a write
        # before storing any row, after TorchRL's writer has moved its cursor).
        partial, position = dict(self._partial), _upstream.writer_position(self)
        try:
            return self._extend(data)
        except Exception:
            self._partial = partial
            _upstream.restore_writer_position(self, position)
            raise

    def _extend(self, data: TensorDictBase) -> torch.Tensor:
        lanes = self._lanes(data)
        ends = lanes.get(self.end_key, None)
        if ends is None:
            raise KeyError(
                f"EpisodeWriter cuts episodes at {self.end_key!r}, which the batch lacks; "
                f"present keys: {sorted(map(str, lanes.keys(True, True)))}"
            )
        ends = ends.reshape(*lanes.shape, -1).any(-1)
        trajectories = lanes.get(self.traj_key, None)
        episodes, pieces = [], []  # pieces: (episode, lane, first step, last step + 1, steps before it)
        for lane in range(lanes.shape[0]):
            start = 0
            for stop in [*(ends[lane].nonzero().squeeze(-1) + 1).tolist(), lanes.shape[1]]:
                if stop == start:
                    continue
                key = lane if trajectories is None else int(trajectories[lane, start])
                before = self._partial.pop(key, None)
                segment = lanes[lane, start:stop]
                if before is not None and not _continues(before, segment):
                    before = None  # the env was reset before that episode ended: it never will
                episode = segment if before is None else torch.cat([before, segment])
                self._check_length(episode, data.shape)
                if bool(ends[lane, stop - 1]):
                    pieces.append((len(episodes), lane, start, stop, 0 if before is None else before.shape[0]))
                    episodes.append(pad(episode, [0, self.max_episode_steps - episode.shape[0]]))
                else:  # a copy: a collector may reuse its batch's memory for the next one
                    self._partial[key] = episode.clone()
                start = stop
        positions = torch.full(lanes.shape, -1, dtype=torch.long)
        if episodes:
            rows = super().extend(torch.stack(episodes))[:: self.max_episode_steps, 0]
            for episode, lane, start, stop, before in pieces:
                first = rows[episode] * self.max_episode_steps + before
                positions[lane, start:stop] = torch.arange(first, first + stop - start)
        return positions.reshape(data.shape)

    def _lanes(self, data: TensorDictBase) -> TensorDictBase:
        """``data`` as ``[lanes, time]``, after checking its time dimension is the last."""
        storage = getattr(self, "_storage", None)  # None until a buffer registers it
        dim_extends = [] if storage is None else [b.dim_extend for b in _upstream.attached_buffers(storage)]
        require_time_at(data, data.ndim - 1, dim_extends)
        lanes = data.unsqueeze(0) if data.ndim == 1 else data.reshape(-1, data.shape[-1])
        if "time" not in data.names and data.ndim > 1:
            self._require_time_last(lanes, data.shape)
        return lanes

    def _require_time_last(self, lanes: TensorDictBase, shape: torch.Size) -> None:
        """Refuses a batch without dimension names whose frames do not follow each other along its last dimension.

        Within a lane, a frame that does not end its episode is followed by the frame whose state is its next-state;
        a ``[T, envs]`` batch read as ``[envs, T]`` breaks that at almost every step.
        """
        ends = lanes.get(self.end_key, None)
        if ends is None or lanes.shape[1] < 2:  # without its end flags, extend() refuses the batch
            return
        following = ~ends.reshape(*lanes.shape, -1).any(-1)[:, :-1]
        after, before = lanes[:, 1:], lanes[:, :-1].get("next")
        for key in before.keys(True, True):
            now = after.get(key, None)
            if now is None or not torch.is_floating_point(now):
                continue
            matches = (now == before.get(key)).reshape(*following.shape, -1).all(-1)
            if (following & ~matches).any():
                raise ValueError(
                    f"the frames of the batch of shape {list(shape)} do not follow each other along its last "
                    f"dimension ({key!r} differs from the previous frame's next {key!r}): EpisodeWriter reads the "
                    "last dimension as time. Give the batch time last ([envs, T], e.g. batch.transpose(0, 1)), or "
                    "name its dimensions as TorchRL's collectors do (names=[..., 'time'])"
                )
            return  # one entry present in both tells

    def _check_length(self, episode: TensorDictBase, shape: torch.Size) -> None:
        if episode.shape[0] > self.max_episode_steps:
            raise ValueError(
                f"an episode of the batch of shape {list(shape)} runs {episode.shape[0]} steps without an end "
                f"flag {self.end_key!r}, more than max_episode_steps={self.max_episode_steps}: give EpisodeWriter "
                "the env's episode length, and a batch whose last dimension is time"
            )

    def _empty(self, empty_write_count: bool = True) -> None:
        super()._empty(empty_write_count=empty_write_count)
        self._partial.clear()

    def state_dict(self) -> dict[str, Any]:
        return {**super().state_dict(), "partial_episodes": self._partial_state()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        super().load_state_dict(state_dict)
        self._load_partial_state(state_dict.get("partial_episodes", {}))  # none in a RoundRobinWriter's state

    def dumps(self, path: str | Path) -> None:
        super().dumps(path)
        torch.save(self._partial_state(), Path(path) / PARTIAL_EPISODES_FILE)

    def loads(self, path: str | Path) -> None:
        super().loads(path)
        self._load_partial_state(torch.load(Path(path) / PARTIAL_EPISODES_FILE, weights_only=True))

    def _partial_state(self) -> dict[int, dict[str, Any]]:
        return {key: frames.apply(torch.clone).state_dict() for key, frames in self._partial.items()}

    def _load_partial_state(self, state: dict[int, dict[str, Any]]) -> None:
        self._partial = {
            key: TensorDict().load_state_dict(frames, strict=False).apply(torch.clone) for key, frames in state.items()
        }

    def __repr__(self) -> str:
        return (
            f"EpisodeWriter(max_episode_steps={self.max_episode_steps}, cursor={int(_upstream.writer_position(self)[0])}, "
            f"partial_episodes={len(self._partial)})"
        )


def _continues(before: TensorDictBase, segment: TensorDictBase) -> bool:
    """Whether ``segment`` starts where ``before`` stopped: its first state is ``before``'s last next-state."""
    last, first = before[-1].get("next"), segment[0]
    present = set(first.keys(True, True))
    return all(torch.equal(value, first.get(key)) for key, value in last.items(True, True) if key in present)
