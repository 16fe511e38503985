"""Train DDPG + HER with a replay sampler on a touch-sensing Fetch task.

    python train.py preset=quick                      # about 20 seconds on 2 CPU cores
    python train.py sampler=cebp env=pick_place
    python train.py -m sampler=her,cebp seed=0,1      # sweep, two jobs at a time
    python train.py sampler=cebp env=pick_place resume=true   # continue after the last finished epoch

Options: conf/config.yaml; groups env={pick_place,push,slide,franka_pick_place,
pick_place_released,push_released,slide_released}, sampler={her,per,ebp,mep,cper,cebp,cebp_released,
cebp_initial}, preset={default,quick,paper}, +comparison=<stage> (conf/comparison/).
"""

import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from torchrl_cebp.training import train
from torchrl_cebp.training.checkpoint import UnreadableFileError


@hydra.main(config_path="conf", config_name="config", version_base="1.3")
def main(cfg: DictConfig) -> None:
    try:
        csv_path = train(cfg, HydraConfig.get().runtime.output_dir)
    except UnreadableFileError as error:  # no checkpoint of the run loads: a message, not a stack trace
        sys.exit(f"error: {error}")
    print(f"per-epoch results: {csv_path}")


if __name__ == "__main__":
    main()
