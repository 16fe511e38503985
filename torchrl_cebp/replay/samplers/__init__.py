"""One TorchRL :class:`~torchrl.data.replay_buffers.Sampler` per replay method of the CEBP paper."""
from torchrl_cebp.replay.samplers.base import EpisodePrioritySampler
from torchrl_cebp.replay.samplers.cebp import CEBPSampler, InitialCEBPSampler, ReleasedCEBPSampler
from torchrl_cebp.replay.samplers.cper import CPERSampler
from torchrl_cebp.replay.samplers.ebp import EBPSampler
from torchrl_cebp.replay.samplers.mep import MEPSampler
from torchrl_cebp.replay.samplers.per import PERSampler
from torchrl_cebp.replay.samplers.per_worker import PerWorkerSampler, WorkerRows, worker_sampler
from torchrl_cebp.replay.samplers.uniform import UniformEpisodeSampler

__all__ = [
    "CEBPSampler",
    "CPERSampler",
    "EBPSampler",
    "EpisodePrioritySampler",
    "InitialCEBPSampler",
    "MEPSampler",
    "PERSampler",
    "PerWorkerSampler",
    "ReleasedCEBPSampler",
    "UniformEpisodeSampler",
    "WorkerRows",
    "worker_sampler",
]
