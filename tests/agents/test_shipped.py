"""The trained Fetch agents that ship in the package: small weights-only files that solve their task."""

import pytest
import torch

from torchrl_cebp.agents import SHIPPED_AGENTS
from torchrl_cebp.agents.shipped import FETCH_AGENTS, SHIPPING_BAR, SUITE_CHECK
from torchrl_cebp.evaluate import success_rate
from torchrl_cebp.training.checkpoint import POLICY_FORMAT


def shipped(task: str):
    if not SHIPPED_AGENTS[task].is_file():
        pytest.skip(f"no {task} agent is shipped in this checkout yet")
    return SHIPPED_AGENTS[task]


@pytest.mark.parametrize("task", FETCH_AGENTS)
def test_a_shipped_agent_is_a_small_weights_only_file_with_its_model_card(task):
    path = shipped(task)
    assert path.stat().st_size < 1_000_000
    state = torch.load(path, map_location="cpu", weights_only=True)
    assert state["format"] == POLICY_FORMAT and state["env"]["task"] == task
    assert state["env"]["goal_space"] == "standard" and state["env"]["control"] == "mocap"  # robot A
    assert state["card"]["success"] >= SHIPPING_BAR[task] and state["card"]["episodes"] == 100


@pytest.mark.parametrize("task", FETCH_AGENTS)
def test_a_shipped_agent_solves_fresh_episodes(task):
    assert SUITE_CHECK[:2] == (10, 777)  # 8 of 10 fresh episodes, as the agents promise
    assert success_rate(shipped(task), episodes=SUITE_CHECK.episodes, seed=SUITE_CHECK.seed) >= SUITE_CHECK.success
