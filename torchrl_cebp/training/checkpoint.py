"""Checkpoints of plain tensors and dicts (loadable with ``weights_only=True``), written atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch

CHECKPOINT_NAME = "checkpoint.pt"


def save_checkpoint(state: dict[str, Any], run_dir: str | Path) -> Path:
    """Writes ``state`` to ``run_dir/checkpoint.pt`` through a temporary file and a rename.

    A crash while writing leaves the previous checkpoint intact.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     _ = save_checkpoint({"epoch": 3, "w": torch.ones(2)}, d)
        ...     load_checkpoint(d)["epoch"]
        3
    """
    path = Path(run_dir) / CHECKPOINT_NAME
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)
    return path


def load_checkpoint(run_dir: str | Path, map_location: torch.device | str = "cpu") -> dict[str, Any]:
    """Loads ``run_dir/checkpoint.pt`` without unpickling code (``weights_only=True``)."""
    return torch.load(Path(run_dir) / CHECKPOINT_NAME, map_location=map_location, weights_only=True)


def has_checkpoint(run_dir: str | Path) -> bool:
    return (Path(run_dir) / CHECKPOINT_NAME).is_file()


def rng_state() -> dict[str, Any]:
    """The torch RNG states (CPU and, when present, CUDA): the samplers, HER and exploration draw from them."""
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
