"""Train DDPG + HER from a checkout: the package's ``python -m torchrl_cebp.train`` (``--help`` lists the options).

    python train.py preset=quick                      # about 20 seconds on 2 CPU cores
    python train.py sampler=cebp env=pick_place resume=true   # continue after the last finished epoch
"""

from torchrl_cebp.train import main

if __name__ == "__main__":
    main()
