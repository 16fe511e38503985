"""One TorchRL :class:`~torchrl.data.replay_buffers.Sampler` per replay method of the CEBP paper."""
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler, EpisodeSampler
from torchrl_cebp.replay.samplers.cebp import CEBPSampler, InitialCEBPSampler, ReleasedCEBPSampler
from torchrl_cebp.replay.samplers.cper import CPERSampler
from torchrl_cebp.replay.samplers.ebp import EBPSampler
from torchrl_cebp.replay.samplers.mep import MEPSampler
from torchrl_cebp.replay.samplers.per import PERSampler
from torchrl_cebp.replay.samplers.per_worker import (EpisodePerWorkerSampler, PerWorkerSampler,
                                                     PrioritizedPerWorkerSampler, WorkerLayout, WorkerRows)
from torchrl_cebp.replay.samplers.uniform import UniformEpisodeSampler

__all__ = [
    "CEBPSampler",
    "CPERSampler",
    "EBPSampler",
    "EpisodePerWorkerSampler",
    "EpisodePrioritySampler",
    "EpisodeSampler",
    "InitialCEBPSampler",
    "MEPSampler",
    "PERSampler",
    "PerWorkerSampler",
    "PrioritizedPerWorkerSampler",
    "ReleasedCEBPSampler",
    "UniformEpisodeSampler",
    "WorkerLayout",
    "WorkerRows",
]
