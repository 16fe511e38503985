"""The image degradations a real camera adds to the synthetic frames of the table."""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

FRAME_SIZE = (480, 640)


def gaussian_noise(frame: np.ndarray, sigma: float = 10.0, seed: int = 0) -> np.ndarray:
    noise = np.random.default_rng(seed).normal(0.0, sigma, frame.shape)
    return np.clip(frame + noise, 0, 255).astype(np.uint8)


def blur(frame: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(frame, (5, 5), 1.5)


def brightness(scale: float, offset: float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
    return lambda frame: np.clip(frame * scale + offset, 0, 255).astype(np.uint8)


def uneven_lighting(frame: np.ndarray) -> np.ndarray:
    # A lamp on one side: brightness falls from 1.2 to 0.5 across the image.
    gain = np.linspace(1.2, 0.5, frame.shape[1])[None, :, None]
    return np.clip(frame * gain, 0, 255).astype(np.uint8)


DEGRADATIONS: dict[str, list[Callable[[np.ndarray], np.ndarray]]] = {
    "clean": [],
    "noise": [gaussian_noise],
    "blur": [blur],
    "dark": [brightness(0.5)],
    "bright": [brightness(1.3, 20)],
    "uneven_lighting": [uneven_lighting],
    "all": [uneven_lighting, blur, gaussian_noise],
}


def degrade(frame: np.ndarray, name: str) -> np.ndarray:
    for step in DEGRADATIONS[name]:
        frame = step(frame)
    return frame
