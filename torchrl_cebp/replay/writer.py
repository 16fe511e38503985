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

    Every leading dimension of a batch is an env lane and the last one is time (the layout of TorchRL's collectors and
    ``rollout``, which name it ``"time"``); the buffer must extend along dimension 0 (``dim_extend=0``). Each lane is
    cut after each ``end_key`` flag and where its ``traj_key`` changes (a flat batch may hold several envs' frames in
    turn: only their ids tell them apart); an episode that ends is padded to ``max_episode_steps`` and written
    round-robin. Frames continue the episode of their ``traj_key`` (else of their lane) only if their first state is its
    last next-state, so an episode cut by a reset is dropped, never merged. ``rb.extend(batch)`` returns each frame's
    flat transition index ``row * max_episode_steps + step``, -1 while its episode has not ended; and ``rb.empty()``
    drops the waiting frames too. The :doc:`replay page </replay>` shows the layouts it takes.

    Args:
        max_episode_steps (int): the storage's row length, the longest episode (``env.max_episode_steps``).
        end_key (NestedKey, optional): the flag that ends an episode. Defaults to ``("next", "done")``.
        traj_key (NestedKey, optional): the trajectory id of each frame, if the batch has it.
            Defaults to ``("collector", "traj_ids")``.
        compilable (bool, optional): whether the writer is compilable (TorchRL's writer argument); if ``True``,
            the writer cannot be shared between processes. Defaults to ``False``.

    Examples:
        >>> from torchrl.data import TensorDictReplayBuffer
        >>> from torchrl_cebp.envs import make_env
        >>> from torchrl_cebp.replay import EpisodeStorage, EpisodeWriter
        >>> frames = make_env("push", seed=0, num_envs=2).rollout(80, break_when_any_done=False)  # 50 steps, then 30
        >>> rb = TensorDictReplayBuffer(storage=EpisodeStorage(100 * 50), writer=EpisodeWriter(50), dim_extend=0)
        >>> index = rb.extend(frames)
        >>> rb.storage.shape, index[:, 48:52].tolist()  # the next episodes' frames wait for their end
        (torch.Size([2, 50]), [[48, 49, -1, -1], [98, 99, -1, -1]])
    """

    def __init__(
        self, max_episode_steps: int, *, end_key: NestedKey = ("next", "done"),
        traj_key: NestedKey = ("collector", "traj_ids"), compilable: bool = False,
    ) -> None:
        super().__init__(compilable=compilable)
        self.max_episode_steps = int(max_episode_steps)
        self.end_key = end_key
        self.traj_key = traj_key
        # The frames of each episode that has not ended yet, by trajectory id (or lane).
        self._partial: dict[int, TensorDictBase] = {}

    def add(self, data: TensorDictBase) -> torch.Tensor:
        """Writes one frame, as :meth:`extend` writes a batch: its flat index, or -1 while its episode has not ended."""
        return self.extend(data.unsqueeze(0)).squeeze(0)

    def extend(self, data: TensorDictBase) -> torch.Tensor:
        """Writes the episodes that ``data``'s frames complete, padded to ``max_episode_steps``; the other frames wait.

        A refused batch changes nothing: neither the waiting frames nor the next row.

        Args:
            data (TensorDictBase): frames whose last dimension is time and whose leading ones are env lanes.

        Returns:
            Each frame's flat transition index ``row * max_episode_steps + step``, shaped as ``data``; -1 while its
            episode has not ended.

        Raises:
            KeyError: the frames lack ``end_key``.
            ValueError: an episode runs longer than ``max_episode_steps``, or time is not the last dimension.
        """
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
        lanes, ends = self._lanes(data)
        trajectories = lanes.get(self.traj_key, None)
        # A flat batch may hold several env lanes one after another: only their trajectory ids tell them apart.
        cuts = ends.clone() if trajectories is None else ends | (trajectories != trajectories.roll(-1, 1))
        cuts[:, -1] = True  # a lane's last piece either ends there or waits for the next batch
        episodes, pieces = [], []  # pieces[i]: episodes[i]'s lane, first step, last step + 1, steps before it
        for lane in range(lanes.shape[0]):
            stops = (cuts[lane].nonzero().squeeze(-1) + 1).tolist()
            for start, stop in zip([0, *stops], stops):
                key = lane if trajectories is None else int(trajectories[lane, start])
                before = self._partial.pop(key, None)
                segment = lanes[lane, start:stop]
                if before is not None and not _continues(before, segment):
                    before = None  # the env was reset before that episode ended: it never will
                episode = segment if before is None else torch.cat([before, segment])
                if episode.shape[0] > self.max_episode_steps:
                    raise ValueError(f"an episode of the batch of shape {list(data.shape)} runs {episode.shape[0]} "
                                     f"steps without an end flag {self.end_key!r}, more than max_episode_steps="
                                     f"{self.max_episode_steps}: give EpisodeWriter the env's episode length, and a "
                                     "batch whose last dimension is time")
                if bool(ends[lane, stop - 1]):
                    pieces.append((lane, start, stop, 0 if before is None else before.shape[0]))
                    episodes.append(pad(episode, [0, self.max_episode_steps - episode.shape[0]]))
                else:  # a copy: a collector may reuse its batch's memory for the next one
                    self._partial[key] = episode.clone()
        positions = torch.full(lanes.shape, -1, dtype=torch.long)
        if episodes:
            rows = super().extend(torch.stack(episodes))[:: self.max_episode_steps, 0]
            for row, (lane, start, stop, before) in zip(rows.tolist(), pieces):
                first = row * self.max_episode_steps + before
                positions[lane, start:stop] = torch.arange(first, first + stop - start)
        return positions.reshape(data.shape)

    def _lanes(self, data: TensorDictBase) -> tuple[TensorDictBase, torch.Tensor]:
        """``data`` as ``[lanes, time]`` and its ``[lanes, time]`` end flags, once its time is known to be last."""
        storage = getattr(self, "_storage", None)  # None until a buffer registers it
        require_time_at(data, data.ndim - 1,
                        lambda: [] if storage is None else [b.dim_extend for b in _upstream.attached_buffers(storage)])
        lanes = data.unsqueeze(0) if data.ndim == 1 else data.reshape(-1, data.shape[-1])
        ends = lanes.get(self.end_key, None)
        if ends is None:
            raise KeyError(f"EpisodeWriter cuts episodes at {self.end_key!r}, which the batch lacks; present keys: "
                           f"{sorted(map(str, lanes.keys(True, True)))}")
        ends = ends.reshape(*lanes.shape, -1).any(-1)
        if "time" not in data.names and data.ndim > 1:
            _require_time_last(lanes, ends, data.shape)
        return lanes, ends

    def _empty(self, empty_write_count: bool = True) -> None:
        super()._empty(empty_write_count=empty_write_count)
        self._partial.clear()

    def state_dict(self) -> dict[str, Any]:
        """TorchRL's writer state and the frames waiting for their episode's end (``"partial_episodes"``)."""
        return {**super().state_dict(), "partial_episodes": self._partial_state()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Loads a :meth:`state_dict`, or a TorchRL round-robin writer's state (then no frames wait)."""
        super().load_state_dict(state_dict)
        self._load_partial_state(state_dict.get("partial_episodes", {}))  # none in a RoundRobinWriter's state

    def dumps(self, path: str | Path) -> None:
        """Writes TorchRL's writer files into the folder ``path``, and the waiting frames beside them."""
        super().dumps(path)
        torch.save(self._partial_state(), Path(path) / PARTIAL_EPISODES_FILE)

    def loads(self, path: str | Path) -> None:
        """Loads what :meth:`dumps` wrote into ``path``."""
        super().loads(path)
        self._load_partial_state(torch.load(Path(path) / PARTIAL_EPISODES_FILE, weights_only=True))

    def _partial_state(self) -> dict[int, dict[str, Any]]:
        return {key: frames.apply(torch.clone).state_dict() for key, frames in self._partial.items()}

    def _load_partial_state(self, state: dict[int, dict[str, Any]]) -> None:
        self._partial = {key: TensorDict().load_state_dict(frames, strict=False).apply(torch.clone)
                         for key, frames in state.items()}

    def __repr__(self) -> str:
        cursor = int(_upstream.writer_position(self)[0])
        return (f"EpisodeWriter(max_episode_steps={self.max_episode_steps}, cursor={cursor}, "
                f"partial_episodes={len(self._partial)})")


def _continues(before: TensorDictBase, segment: TensorDictBase) -> bool:
    """Whether ``segment`` starts where ``before`` stopped: its first state is ``before``'s last next-state."""
    last, first = before[-1].get("next"), segment[0]
    return all(torch.equal(value, first.get(key, value)) for key, value in last.items(True, True))


def _require_time_last(lanes: TensorDictBase, ends: torch.Tensor, shape: torch.Size) -> None:
    """Refuses an unnamed batch whose frames do not follow each other along its last dimension.

    A ``[T, envs]`` batch read as ``[envs, T]`` breaks the chain of next-states at almost every step.
    """
    following = ~ends[:, :-1]
    after, before = lanes[:, 1:], lanes[:, :-1].get("next")
    for key in before.keys(True, True):
        now = after.get(key, None)
        if now is None or not torch.is_floating_point(now):
            continue
        matches = (now == before.get(key)).reshape(*following.shape, -1).all(-1)
        if (following & ~matches).any():
            raise ValueError(f"the frames of the batch of shape {list(shape)} do not follow each other along its "
                             f"last dimension ({key!r} differs from the previous frame's next {key!r}): EpisodeWriter "
                             "reads the last dimension as time. Give the batch time last ([envs, T], e.g. "
                             "batch.transpose(0, 1)), or name its dimensions as TorchRL's collectors do (names=[..., "
                             "'time'])")
        return  # one entry present in both tells
