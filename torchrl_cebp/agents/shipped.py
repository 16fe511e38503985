"""The trained agents that ship inside the package, one per task."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

from torchrl_cebp.envs.goal_spaces import TASKS

__all__ = ["FETCH_AGENTS", "SHIPPED_AGENTS", "SHIPPING_BAR", "SUITE_CHECK", "shipped_agent"]

_PACKAGE = Path(__file__).parents[1]

# Actor and observation normaliser only (a policy file of torchrl_cebp.training.save_policy), loaded with
# weights_only=True. The Fetch agents are robot A's (the mocap Fetch on the standard goal space, the paper's figure).
SHIPPED_AGENTS: dict[str, Path] = {
    "pick_place": _PACKAGE / "agents" / "policies" / "pick_place.pt",
    "push": _PACKAGE / "agents" / "policies" / "push.pt",
    "franka_pick_place": _PACKAGE / "sim2real" / "policies" / "franka_pick_place_cebp.pt",
}

# The Fetch tasks' agents (robot A's), whose cards docs/agents.md carries; the Franka policy's page is the Sim2Real one.
FETCH_AGENTS: tuple[str, ...] = tuple(task for task in SHIPPED_AGENTS if task in TASKS)

# The success over 100 fresh episodes an agent needs before it ships (the Franka one: of the camera loop's length).
SHIPPING_BAR: dict[str, float] = {"pick_place": 0.85, "push": 0.95, "franka_pick_place": 0.8}


class SuiteCheck(NamedTuple):
    """What the test suite asks of every shipped Fetch agent: ``success`` over ``episodes`` episodes from ``seed`` on,
    seeds that neither the trainer's test episodes nor the card's score used.

    Example:
        >>> SUITE_CHECK.episodes, SUITE_CHECK.seed, SUITE_CHECK.success
        (10, 777, 0.8)
    """

    episodes: int
    seed: int
    success: float


# 8 of 10 fresh episodes; the ship script refuses an agent that would fail it.
SUITE_CHECK = SuiteCheck(episodes=10, seed=777, success=0.8)


def shipped_agent(task: str) -> Path:
    """The policy file of the agent shipped for ``task``, for ``evaluate``, ``load_policy`` or the Sim2Real loop.

    Args:
        task (str): one of :data:`SHIPPED_AGENTS`' keys.

    Raises:
        ValueError: no agent is planned for ``task``; the message names the tasks that have one.
        FileNotFoundError: this installation lacks the file (a checkout from before the agent shipped).

    Example:
        >>> shipped_agent("franka_pick_place").name
        'franka_pick_place_cebp.pt'
        >>> shipped_agent("slide")
        Traceback (most recent call last):
        ...
        ValueError: no agent ships for task 'slide'; tasks with one: ['franka_pick_place', 'pick_place', 'push']
    """
    if task not in SHIPPED_AGENTS:
        raise ValueError(f"no agent ships for task {task!r}; tasks with one: {sorted(SHIPPED_AGENTS)}")
    path = SHIPPED_AGENTS[task]
    if not path.is_file():
        shipped = sorted(name for name, file in SHIPPED_AGENTS.items() if file.is_file())
        raise FileNotFoundError(
            f"the {task} agent is not in this installation ({path} is missing); shipped here: {shipped}. "
            f"Train one at the paper's scale (`python train.py preset=paper env={task}`; the agents page of the docs "
            "gives each shipped agent's command) and pass its run folder instead."
        )
    return path

