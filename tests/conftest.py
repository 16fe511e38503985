import os

os.environ.setdefault("MUJOCO_GL", "osmesa")

import torch

# Two cores: one torch thread keeps the test processes from oversubscribing the machine.
torch.set_num_threads(1)
