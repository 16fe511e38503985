"""Goal-space settings of the touch-sensing Fetch tasks.

``standard`` reproduces gymnasium-robotics' Fetch v4 defaults; ``extended`` is CPER's
(Vulin et al.), the one the CEBP paper reports on.
"""

from __future__ import annotations

from dataclasses import dataclass

TASKS: tuple[str, ...] = ("pick_place", "push", "slide")
GOAL_SPACES: tuple[str, ...] = ("standard", "extended")


@dataclass(frozen=True)
class GoalSpace:
    """Where objects start and targets appear, and when a task counts as solved.

    Example:
        >>> from torchrl_cebp.envs.goal_spaces import get_goal_space
        >>> get_goal_space("slide", "extended").max_episode_steps
        70
    """

    target_offset: tuple[float, float, float]
    obj_range: float
    target_range: float
    distance_threshold: float = 0.05
    max_episode_steps: int = 50
    # Table half-size (x, y); None keeps the XML's table.
    table_half_size: tuple[float, float] | None = None
    # If set, every target is lifted by U(0, target_height) (gymnasium lifts only half of them).
    target_height: float | None = None
    # CPER starts the Slide puck obj_range further from the robot.
    shift_object_x: bool = False


_GOAL_SPACES: dict[tuple[str, str], GoalSpace] = {
    ("pick_place", "standard"): GoalSpace((0.0, 0.0, 0.0), 0.15, 0.15),
    ("push", "standard"): GoalSpace((0.0, 0.0, 0.0), 0.15, 0.15),
    ("slide", "standard"): GoalSpace((0.4, 0.0, 0.0), 0.1, 0.3),
    ("pick_place", "extended"): GoalSpace((0.2, 0.0, 0.0), 0.15, 0.15, target_height=0.35),
    ("push", "extended"): GoalSpace((0.1, 0.0, 0.0), 0.25, 0.25, table_half_size=(0.5, 0.5)),
    ("slide", "extended"): GoalSpace(
        (1.0, 0.0, 0.0),
        0.1,
        0.6,
        distance_threshold=0.15,
        max_episode_steps=70,
        table_half_size=(1.2, 1.0),
        shift_object_x=True,
    ),
}


def get_goal_space(task: str, goal_space_name: str) -> GoalSpace:
    """The :class:`GoalSpace` of ``task`` under ``goal_space_name``; ValueError listing the valid names if unknown.

    Example:
        >>> from torchrl_cebp.envs.goal_spaces import get_goal_space
        >>> get_goal_space("push", "extended").table_half_size
        (0.5, 0.5)
    """
    if task not in TASKS:
        raise ValueError(f"Unknown task {task!r}; valid tasks: {', '.join(TASKS)}")
    if goal_space_name not in GOAL_SPACES:
        raise ValueError(f"Unknown goal space {goal_space_name!r}; valid goal spaces: {', '.join(GOAL_SPACES)}")
    return _GOAL_SPACES[(task, goal_space_name)]
