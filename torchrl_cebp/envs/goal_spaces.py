"""Goal-space settings of the touch-sensing Fetch tasks.

``standard`` reproduces gymnasium-robotics' Fetch v4 defaults: the goal space of the Initial commit,
on which the paper's Fig. 2 was made. ``extended`` is CPER's (Vulin et al.): the one the paper's text
describes and the released code uses.
"""

from __future__ import annotations

from dataclasses import dataclass

TASKS: tuple[str, ...] = ("pick_place", "push", "slide")
GOAL_SPACES: tuple[str, ...] = ("standard", "extended")


@dataclass(frozen=True)
class GoalSpace:
    """Where objects start and targets appear, and when a task counts as solved.

    Args:
        target_offset (tuple of float): offset of the target region's centre from the gripper's start (x, y, z).
        obj_range (float): half-width of the square the object starts in.
        target_range (float): half-width of the square the target appears in.
        distance_threshold (float, optional): the success radius. Defaults to ``0.05``.
        max_episode_steps (int, optional): the episode length. Defaults to ``50``.
        table_half_size (tuple of float, optional): the table's half-size (x, y); ``None`` keeps the XML's
            table. Defaults to ``None``.
        target_height (float, optional): if set, every target is lifted by ``U(0, target_height)``
            (gymnasium lifts only half of them). Defaults to ``None``.
        shift_object_x (bool, optional): start the object ``obj_range`` further from the robot (CPER's
            Slide). Defaults to ``False``.

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
    table_half_size: tuple[float, float] | None = None
    target_height: float | None = None
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
    """The :class:`GoalSpace` of ``task`` under ``goal_space_name``.

    Args:
        task (str): ``"pick_place"``, ``"push"`` or ``"slide"``.
        goal_space_name (str): ``"standard"`` or ``"extended"``.

    Raises:
        ValueError: an unknown task or goal space; the message lists the valid names.

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
