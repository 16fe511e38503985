import os

os.environ.setdefault("MUJOCO_GL", "osmesa")

import pytest
import torch
import tensordict  # noqa: F401  (before mujoco: tensordict's triton import crashes once OSMesa is loaded)

from tests.tiny_run import TINY_RUN, config

# Two cores: one torch thread keeps the test processes from oversubscribing the machine.
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory):
    """A run directory of the tiny config (:data:`tests.tiny_run.TINY_RUN`), trained once a session; read only:
    a test that changes it works on :func:`tests.tiny_run.copy_run`."""
    from torchrl_cebp.training import train

    run_dir = tmp_path_factory.mktemp("tiny_run")
    train(config(*TINY_RUN), run_dir)
    return run_dir
