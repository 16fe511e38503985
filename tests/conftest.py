import os

os.environ.setdefault("MUJOCO_GL", "osmesa")

import torch
import tensordict  # noqa: F401  (before mujoco: tensordict's triton import crashes once OSMesa is loaded)

# Two cores: one torch thread keeps the test processes from oversubscribing the machine.
torch.set_num_threads(1)
