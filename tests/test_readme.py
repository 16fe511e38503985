"""The README's examples run as written."""
import doctest
import logging
import re
import socket
from pathlib import Path

import torchrl  # noqa: F401  (it sets its logger's level on import: import it before quieting it)

README = Path(__file__).parents[1] / "README.md"
TRAINING_PAGE = Path(__file__).parents[1] / "docs" / "training.md"  # the distributed collector example lives there


def test_the_readme_sampler_example_runs_as_written():
    # TorchRL logs storage initialisation to stdout, which doctest would read as output.
    torchrl_logger = logging.getLogger("torchrl")
    level = torchrl_logger.level
    torchrl_logger.setLevel(logging.WARNING)
    try:
        failures, tried = doctest.testfile(str(README), module_relative=False, optionflags=doctest.ELLIPSIS)
    finally:
        torchrl_logger.setLevel(level)
    assert tried >= 10 and failures == 0


def test_the_readme_distributed_collector_example_runs_on_local_processes():
    blocks = re.findall(r"```python\n(.*?)```", TRAINING_PAGE.read_text(), flags=re.DOTALL)
    example = next(block for block in blocks if "DistributedSyncCollector(" in block)
    with socket.socket() as probe:  # a free port for the collector's process group
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    # The same code with node processes on this machine instead of Slurm jobs, and less of everything.
    slurm = 'launcher="submitit", slurm_kwargs={"partition": "cpu", "timeout_min": 600}'
    on_this_machine = {
        slurm: f'launcher="mp", tcp_port="{port}"',
        "nodes, envs, T = 4, 16, 50": "nodes, envs, T = 2, 2, 50",
        "total_frames=100 * nodes": "total_frames=2 * nodes",
        "capacity=1_000_000": "capacity=100 * T",
    }
    for text, replacement in on_this_machine.items():
        assert example.count(text) == 1, text
        example = example.replace(text, replacement)
    namespace = {}
    exec(example, namespace)
    rb = namespace["rb"]
    assert rb.storage.shape == (2 * 2 * 2, 50)  # 2 batches of [2 nodes, 2 envs, 50 steps]: 8 episodes
    assert rb.sample()["next", "reward"].shape == (256, 1)
