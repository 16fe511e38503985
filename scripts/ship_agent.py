"""Ships a trained Fetch agent: scores it on fresh episodes, and if it clears its task's bar, writes it into the package
with its model card, a video and a frame strip.

The policy file (a run's ``best_policy.pt`` or ``policy.pt``) is scored over ``--episodes`` fresh episodes with
``evaluate``'s measure, from seeds the trainer's test episodes never used. At or above the task's bar
(``torchrl_cebp.agents.SHIPPING_BAR``: 0.85 for PickAndPlace, 0.95 for Push) it is written to the package
(``torchrl_cebp.agents.SHIPPED_AGENTS``) with a model card: the sampler, the training command, the code commit and
training time of its run (from the run's ``progress.csv``), and the score. It must also pass the test suite's
check (``SUITE_CHECK``: 8 of 10 episodes from other fresh seeds). The card's command is the run's ``train.py``
overrides (its ``.hydra/overrides.yaml``, or ``--overrides``), checked against the run's checkpoint: it rebuilds the run.
Then it writes ``docs/img/agent_<task>.mp4`` (two episodes), ``docs/img/agent_<task>_frames.png`` (six frames of
the first half of one episode) and the cards of every shipped agent into ``docs/agents.md``.

    .venv/bin/python scripts/ship_agent.py push runs/push-standard/ebp/paper-per_worker/seed0/best_policy.pt
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
AGENTS_PAGE = REPO / "docs" / "agents.md"
CARDS_START, CARDS_END = "<!-- model cards: written by scripts/ship_agent.py -->", "<!-- end of model cards -->"
# The trainer seeds its test episodes from a hash of (seed, epoch) (derive_seed): a run of plain seeds misses them.
FRESH_SEED = 10_000
STRIP_FRAMES = 6


def main(argv: list[str] | None = None) -> int:
    from torchrl_cebp.agents.shipped import FETCH_AGENTS

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("task", choices=FETCH_AGENTS, help="the task the agent ships for")
    parser.add_argument("policy", type=Path, help="the run's best_policy.pt or policy.pt")
    parser.add_argument("--overrides", nargs="+", metavar="OVERRIDE",
                        help="the run's train.py overrides, checked against its checkpoint (default: the run folder's "
                        ".hydra/overrides.yaml)")
    parser.add_argument("--episodes", type=int, default=100, help="fresh episodes for the score")
    parser.add_argument("--force", action="store_true", help="ship even below the task's bar")
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    try:
        overrides = args.overrides or run_overrides(args.policy.parent)
        state = card_state(args.task, args.policy, overrides, args.episodes)
    except (ValueError, FileNotFoundError) as error:
        parser.exit(2, f"error: {error}\n")
    ship(args.task, state, args.force)
    return 0


def run_overrides(run_dir: Path) -> list[str]:
    """The ``train.py`` overrides Hydra saved in the run folder."""
    from omegaconf import OmegaConf

    path = run_dir / ".hydra" / "overrides.yaml"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: pass the run's train.py overrides with --overrides")
    return list(OmegaConf.load(path))


def card_state(task: str, policy: Path, overrides: list[str], episodes: int) -> dict:
    """The policy file's state with its ``card``, after the checks that it is the task's agent and its command."""
    from torchrl_cebp.agents.shipped import SUITE_CHECK
    from torchrl_cebp.evaluate import success_rate
    from torchrl_cebp.training.checkpoint import RunCheckpoints, read_policy_state
    from torchrl_cebp.training.config import check_same_run, compose_config
    from torchrl_cebp.training.metrics import CSV_NAME

    state = read_policy_state(policy)
    if state["env"]["task"] != task:
        raise ValueError(f"{policy} was trained on {state['env']['task']!r}, not {task!r}")
    run_dir = policy.parent
    saved = RunCheckpoints(run_dir).load()["config"]
    check_same_run(saved, compose_config(*overrides))
    with open(run_dir / CSV_NAME, newline="") as file:
        rows = list(csv.DictReader(file))
    score = success_rate(policy, episodes, FRESH_SEED)
    print(f"[ship] {policy}: {episodes} fresh episodes (seeds {FRESH_SEED}+): success {score:.3f}")
    suite = success_rate(policy, SUITE_CHECK.episodes, SUITE_CHECK.seed)
    print(f"[ship] the test suite's {SUITE_CHECK.episodes} episodes (seed {SUITE_CHECK.seed}): {suite:.3f}")
    last = rows[-1]
    card = {
        "sampler": f"{saved['sampler']['_target_'].rsplit('.', 1)[1]}, HER '{saved['replay']['strategy']}'",
        "command": " ".join(["python train.py", *overrides]),
        "code_commit": last["code_commit"],
        "epochs": len(rows),
        "training_hours": float(last["wall_s"]) / 3600,
        "cpu": f"one CPU thread ({last.get('cpu_capability') or 'unknown'})",
        "epoch": int(state["epoch"]),
        "test_success": float(state["test_success"]),
        "success": score,
        "episodes": episodes,
        "seed": FRESH_SEED,
        "suite_check": suite,
    }
    return {**state, "card": card}


def ship(task: str, state: dict, force: bool) -> None:
    """Writes the policy file, its video and frame strip, and the agents page's cards; refuses below the bar."""
    from torchrl_cebp.agents.shipped import SHIPPED_AGENTS, SHIPPING_BAR, SUITE_CHECK
    from torchrl_cebp.evaluate import render_episodes, write_video
    from torchrl_cebp.training.checkpoint import save_policy

    score, bar = state["card"]["success"], SHIPPING_BAR[task]
    if score < bar and not force:
        sys.exit(f"[ship] {score:.3f} is below the {task} bar of {bar}: not shipped (--force ships it anyway)")
    suite = state["card"]["suite_check"]
    if suite < SUITE_CHECK.success and not force:
        sys.exit(f"[ship] {suite:.3f} over the test suite's {SUITE_CHECK.episodes} episodes (seed {SUITE_CHECK.seed}) "
                 f"is below its {SUITE_CHECK.success}: not shipped, the suite would fail")
    path = SHIPPED_AGENTS[task]
    path.parent.mkdir(parents=True, exist_ok=True)
    save_policy(state, path)
    print(f"[ship] wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
    frames = render_episodes(path, episodes=2, seed=FRESH_SEED)
    video, strip = (REPO / "docs" / name for name in media(task))
    print(f"[ship] wrote {write_video(frames, video)}")
    first_half = frames[: len(frames) // 4 + 1]  # of the first episode: the object moves early, then rests at the goal
    print(f"[ship] wrote {write_frame_strip(first_half, strip)}")
    write_cards(AGENTS_PAGE)
    print(f"[ship] wrote the model cards into {AGENTS_PAGE}")


def media(task: str) -> tuple[str, str]:
    """The agent's video and frame strip, relative to ``docs/``."""
    return f"img/agent_{task}.mp4", f"img/agent_{task}_frames.png"


def model_card(task: str, state: dict) -> str:
    """A Markdown section on a shipped agent, from the ``card`` its policy file carries, with its frame strip."""
    from torchrl_cebp.agents.shipped import SHIPPED_AGENTS

    card = state["card"]
    rows = {
        "task": f"`{task}`, goal space `{state['env']['goal_space']}`, control `{state['env']['control']}`",
        "sampler": card["sampler"],
        "trained with": f"`{card['command']}`",
        "code commit": f"`{card['code_commit']}`",
        "training": f"{card['epochs']} epochs, {card['training_hours']:.1f} h on {card['cpu']}; this file is the "
        f"policy after {card['epoch'] + 1} of them (test success {card['test_success']:.2f} in training)",
        "success": f"{card['success']:.2f} over {card['episodes']} fresh episodes: "
        f"`python -m torchrl_cebp.evaluate --task {task} --episodes {card['episodes']} --seed {card['seed']}`",
        "file": f"`torchrl_cebp.agents.shipped_agent({task!r})`: the actor and observation normaliser, "
        f"{SHIPPED_AGENTS[task].stat().st_size / 1e3:.0f} KB, loaded with `weights_only=True`",
    }
    video, strip = media(task)
    table = "\n".join(f"| {name} | {value} |" for name, value in rows.items())
    return (
        f"## {task}: success {card['success']:.2f} over {card['episodes']} fresh episodes\n\n| | |\n|---|---|\n{table}\n\n"
        f"![The {task} agent: six frames of the first half of an episode]({strip})\n\n[Two episodes (MP4)]({video})\n"
    )


def write_frame_strip(frames: list[np.ndarray], path: Path) -> Path:
    """:data:`STRIP_FRAMES` of ``frames``, evenly spaced from the first to the last, side by side, at half size."""
    import imageio.v3 as iio

    picks = np.linspace(0, len(frames) - 1, STRIP_FRAMES).round().astype(int)
    iio.imwrite(path, np.concatenate([frames[i][::2, ::2] for i in picks], axis=1))
    return path


def write_cards(page: Path) -> None:
    """Replaces the text between the page's card markers with the cards of every shipped Fetch agent."""
    from torchrl_cebp.agents.shipped import FETCH_AGENTS, SHIPPED_AGENTS
    from torchrl_cebp.training.checkpoint import read_policy_state

    cards = [model_card(task, read_policy_state(SHIPPED_AGENTS[task])) for task in FETCH_AGENTS
             if SHIPPED_AGENTS[task].is_file()]
    text = page.read_text()
    head, rest = text.split(CARDS_START)
    tail = rest.split(CARDS_END)[1]
    page.write_text(f"{head}{CARDS_START}\n\n" + "\n".join(cards) + f"\n{CARDS_END}{tail}")


if __name__ == "__main__":
    sys.exit(main())
