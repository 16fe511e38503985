"""Contact Energy Based Hindsight Experience Prioritization (CEBP) and its baselines, as TorchRL components."""

__version__ = "0.1.0"
