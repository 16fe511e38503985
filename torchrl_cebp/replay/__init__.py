"""Episode replay: storage of ``[episode, t]`` rows, HER relabelling, and the samplers."""
from torchrl_cebp.replay.buffer import EpisodeReplayBuffer, make_replay_buffer
from torchrl_cebp.replay.episodes import episode_lengths
from torchrl_cebp.replay.her import HindsightRelabel
from torchrl_cebp.replay.storage import EpisodeMemmapStorage, EpisodeStorage, episode_rows
from torchrl_cebp.replay.transforms import replay_cat_tensors
from torchrl_cebp.replay.writer import EpisodeWriter

__all__ = [
    "EpisodeMemmapStorage",
    "EpisodeReplayBuffer",
    "EpisodeStorage",
    "EpisodeWriter",
    "HindsightRelabel",
    "episode_lengths",
    "episode_rows",
    "make_replay_buffer",
    "replay_cat_tensors",
]
