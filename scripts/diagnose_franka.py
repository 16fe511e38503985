"""Can the Franka pick-and-place be learnt as Fetch PickAndPlace is? The checks made before any training.

Each check runs the real MuJoCo envs through their public API (the Franka env and gymnasium-robotics' Fetch
PickAndPlace with touch pads, standard goals: the one the paper's HER learns to lift by about epoch 20):

  * physics: friction, finger actuators, cube mass and size, the squeeze and the hand's speed, Franka beside Fetch;
  * grasp and lift: a scripted grasp carried to the highest goals (0.45 m above the table) at the policy's top speed
    (action magnitude 1, i.e. the action scale), over ``--placements`` placements; then held cubes shaken by 30 steps
    of random full-speed moves, as exploration moves them;
  * reach: the goal space and the workspace box with the hand pointing down, and where the bare arm cannot go;
  * observation: what it tells the policy about the grip, against Fetch's;
  * schedule: ``gamma = 1 - 1/T`` and updates per env step of the Franka config against Fetch's at the paper's scale;
  * a policy (``--policy``, the shipped one by default; ``none`` skips it): success on table and air goals, how often
    it commands a move out of the workspace box, whether it grasps;
  * with ``--replay RUN_DIR`` instead: how often a training run's exploration lifted the cube, epoch by epoch.

Progress goes to stdout as it runs; the figures are printed together at the end.

Example:
    $ MUJOCO_GL=osmesa python scripts/diagnose_franka.py --placements 50
    $ MUJOCO_GL=osmesa python scripts/diagnose_franka.py --only-policy --policy runs/.../best_policy.pt --placements 40
    $ python scripts/diagnose_franka.py --replay runs/franka_pick_place-standard/cebp/paper-per_worker/seed0
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from dataclasses import dataclass

os.environ.setdefault("MUJOCO_GL", "osmesa")

import numpy as np  # noqa: E402
import torch  # noqa: E402  (torchrl_cebp imports tensordict before mujoco)
from omegaconf import OmegaConf  # noqa: E402
from tensordict import TensorDict  # noqa: E402

from torchrl_cebp.envs import FETCH_OBSERVATION as OBS  # noqa: E402
from torchrl_cebp.envs import FrankaPickPlaceEnv, make_touch_fetch  # noqa: E402
from torchrl_cebp.envs.franka import HAND_BODY, HAND_QUAT, FrankaLayout, Workspace  # noqa: E402
from torchrl_cebp.envs.scripted import ACTION_SCALE, GraspAndLift, move_towards  # noqa: E402
from torchrl_cebp.sim2real import SHIPPED_POLICY  # noqa: E402
from torchrl_cebp.training import load_checkpoint, load_policy  # noqa: E402
from torchrl_cebp.training.checkpoint import stored_episodes  # noqa: E402
from torchrl_cebp.training.builders import episodes_per_cycle  # noqa: E402
from torchrl_cebp.training.config import compose_config  # noqa: E402

# gymnasium-robotics' Fetch draws goals in the air up to 0.45 m above the object's resting height.
FETCH_AIR_HEIGHT = 0.45
# Each env's pad geom and finger actuator, to read the physical parameters from.
PAD_GEOM = {"franka": "robot0:left_pad_geom", "fetch": "robot0:l_gripper_finger_link"}
HELD = 0.03  # a cube further than this from the grip point has left the fingers


def make_envs() -> dict[str, object]:
    """The two gymnasium envs: the Franka task and Fetch PickAndPlace (standard goals), both with touch pads."""
    return {"franka": FrankaPickPlaceEnv(), "fetch": make_touch_fetch("pick_place")}


def highest_goal_z(env) -> float:
    """Height of the highest goal of ``env``'s goal space (robot/world frame)."""
    if isinstance(env, FrankaPickPlaceEnv):
        return env.layout.cube_centre_height + env.layout.target_height
    return env.height_offset + FETCH_AIR_HEIGHT


@dataclass
class Lift:
    """One scripted grasp-and-lift episode: success at its end, first success step, cube lost from the fingers."""

    success: bool
    first_success: int | None
    dropped: bool
    max_offset: float


def lift_to_highest_goal(env, seed: int) -> Lift:
    """Resets ``env`` (placement ``seed``), raises the goal to the highest and runs :class:`GraspAndLift`."""
    obs, _ = env.reset(seed=seed)
    goal = obs["desired_goal"].copy()
    goal[2] = highest_goal_z(env)
    env.goal = goal  # as the Sim2Real twin sets its goals
    script, first, dropped, offset, info = GraspAndLift(), None, False, 0.0, {}
    for t in range(env.max_episode_steps):
        carrying = script.phase == "carry"
        obs, _, _, _, info = env.step(script(obs["observation"], goal))
        if carrying:
            distance = float(np.linalg.norm(obs["observation"][OBS.object_relative_position]))
            offset, dropped = max(offset, distance), dropped or distance > HELD
        if first is None and info["is_success"]:
            first = t + 1
    return Lift(bool(info["is_success"]), first, dropped, offset)


def shaken_and_held(env, seed: int, steps: int = 30) -> bool:
    """Grasps the cube, lifts it 15 cm, moves at full speed in random directions; is it still between the fingers?"""
    obs, _ = env.reset(seed=seed)
    goal, script = obs["observation"][OBS.object_position] + [0.0, 0.0, 0.15], GraspAndLift()
    for _ in range(env.max_episode_steps):
        obs, *_ = env.step(script(obs["observation"], goal))
        if script.phase == "carry" and obs["observation"][OBS.gripper_position][2] > goal[2] - 0.01:
            break
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, *_ = env.step(np.append(rng.uniform(-1, 1, 3), -1.0).astype(np.float32))
    return bool(np.linalg.norm(obs["observation"][OBS.object_relative_position]) < HELD)


def physics(name: str, env) -> dict[str, str]:
    """The physical parameters of the grasp, read from the compiled model and measured by stepping ``env``."""
    m = env.model
    cube, pad = m.geom("object0"), m.geom(PAD_GEOM[name])
    kp, damping = m.actuator_gainprm[0, 0], m.dof_damping[m.jnt_dofadr[m.actuator_trnid[0, 0]]]
    limited = "none" if not m.actuator_forcelimited[0] else f"+-{m.actuator_forcerange[0, 1]:.0f} N"
    target = f"clamped to {m.actuator_ctrlrange[0].round(3).tolist()}" if m.actuator_ctrllimited[0] else "unclamped"
    obs, _ = env.reset(seed=0)
    rise = []
    for _ in range(3):
        before = obs["observation"][OBS.gripper_position][2]
        obs, *_ = env.step(np.array([0.0, 0.0, 1.0, 1.0], np.float32))
        rise.append(obs["observation"][OBS.gripper_position][2] - before)
    squeeze = grasp_squeeze(env)
    return {
        "cube mass": f"{m.body_mass[cube.bodyid[0]]:.2f} kg",
        "cube edge": f"{2 * cube.size[0] * 100:.1f} cm",
        "cube friction (slide, torsion, roll)": str(cube.friction.round(4).tolist()),
        "pad friction (slide, torsion, roll)": str(pad.friction.round(4).tolist()),
        "pad size (half, m)": str(pad.size.round(4).tolist()),
        "contact dims cube / pad": f"{cube.condim[0]} / {pad.condim[0]}",
        "finger actuator kp": f"{kp:.0f} N/m",
        "finger position target": target,
        "finger force limit": limited,
        "finger joint damping": f"{damping:.0f} N s/m",
        "squeeze per pad, cube grasped": f"{squeeze:.1f} N",
        "squeeze / cube weight": f"{2 * squeeze / (9.81 * m.body_mass[cube.bodyid[0]]):.0f}",
        "hand rise per step at action 1": f"{np.mean(rise) * 100:.2f} cm (scale {ACTION_SCALE * 100:.0f} cm)",
        "physics step x substeps": f"{m.opt.timestep * 1000:.0f} ms x {env.n_substeps}",
        "mocap weld solref": str(m.eq_solref[0].round(3).tolist()),
    }


def grasp_squeeze(env) -> float:
    """The smaller pad's touch (N) once :class:`GraspAndLift` has closed on the cube of placement 0."""
    obs, _ = env.reset(seed=0)
    script, goal, info = GraspAndLift(), obs["observation"][OBS.object_position] + [0.0, 0.0, 0.1], {}
    for _ in range(env.max_episode_steps):
        obs, _, _, _, info = env.step(script(obs["observation"], goal))
        if script.phase == "carry":
            break
    return float(info["touch"].min())


def widths(env) -> dict[str, float]:
    """The observed gripper opening (sum of the finger positions): open, closed on the cube, closed on nothing."""
    obs, _ = env.reset(seed=0)
    script, goal = GraspAndLift(), obs["observation"][OBS.object_position] + [0.0, 0.0, 0.1]
    out = {}
    for _ in range(env.max_episode_steps):
        if script.phase == "descend":
            out["open"] = float(OBS.gripper_opening(obs["observation"]))
        obs, *_ = env.step(script(obs["observation"], goal))
        if script.phase == "carry":
            break
    out["on the cube"] = float(OBS.gripper_opening(obs["observation"]))
    out["grip-to-cube offset, grasped"] = float(np.linalg.norm(obs["observation"][OBS.object_relative_position]))
    for _ in range(8):
        obs, *_ = env.step(np.array([0.0, 0.0, 0.0, 1.0], np.float32))
    for _ in range(3):
        obs, *_ = env.step(np.array([0.0, 0.0, 1.0, 1.0], np.float32))  # away from the cube
    for _ in range(8):
        obs, *_ = env.step(np.array([0.0, 0.0, 0.0, -1.0], np.float32))
    out["closed on nothing"] = float(OBS.gripper_opening(obs["observation"]))
    return out


@dataclass
class Reach:
    """Whether the grip point got to ``target`` with the hand pointing down, and how far off it stayed."""

    target: tuple[float, float, float]
    error: float
    tilt_deg: float
    swing: float
    joint_margin: float
    blocked: bool

    @property
    def reached(self) -> bool:
        return self.error < 0.005 and self.tilt_deg < 3.0 and self.swing < 0.001


def reach(env: FrankaPickPlaceEnv, target: np.ndarray, steps: int = 40) -> Reach:
    """Drives the grip point to ``target`` (over the table first, fingers open) and measures the last steps."""
    obs, _ = env.reset(seed=0)
    cube, grips = obs["observation"][OBS.object_position].copy(), []
    above = np.array([*target[:2], max(target[2], 0.3)])
    for t in range(steps):
        waypoint = above if t < steps // 2 and np.linalg.norm(above[:2] - obs["observation"][:2]) > 0.005 else target
        obs, *_ = env.step(move_towards(obs["observation"][OBS.gripper_position], waypoint, 1.0))
        grips.append(obs["observation"][OBS.gripper_position].copy())
    last = np.array(grips[-6:])
    quat = env.data.body(HAND_BODY).xquat
    q, limits = env.data.qpos[:7], env.model.jnt_range[:7]
    return Reach(
        target=tuple(float(v) for v in target),
        error=float(np.linalg.norm(last[-1] - target)),
        tilt_deg=float(2 * np.degrees(np.arccos(min(1.0, abs(float(np.dot(quat, HAND_QUAT))))))),
        swing=float(last.std(0).max()),
        joint_margin=float(np.minimum(q - limits[:, 0], limits[:, 1] - q).min()),
        blocked=bool(np.linalg.norm(obs["observation"][OBS.object_position] - cube) > 0.005),  # the fingers hit it
    )


def reach_grid(env: FrankaPickPlaceEnv, xs, ys, zs, label: str) -> list[Reach]:
    points = list(itertools.product(xs, ys, zs))
    print(f"  reach: {label}, {len(points)} points", flush=True)
    return [reach(env, np.array(p)) for p in points]


def schedules() -> dict[str, dict[str, float]]:
    """The training schedule of Fetch PickAndPlace and of the Franka task at the paper's scale (torchrl_cebp/conf/)."""
    runs = {
        "Fetch PickAndPlace, preset=paper": ["env=pick_place", "preset=paper"],
        "Franka, preset=paper": ["env=franka_pick_place", "preset=paper"],
        "Franka, preset=paper rollouts_per_cycle=1": ["env=franka_pick_place", "preset=paper", "rollouts_per_cycle=1"],
    }
    out = {}
    for label, overrides in runs.items():
        cfg = compose_config(*overrides)
        env = FrankaPickPlaceEnv() if cfg.env.task == "franka_pick_place" else make_touch_fetch(cfg.env.task)
        steps = env.max_episode_steps
        gamma = 1.0 - 1.0 / steps  # HER's discount, as torchrl_cebp.training.builders.make_agent sets it
        env_steps = episodes_per_cycle(cfg) * steps
        batch = cfg.batch_size * cfg.workers
        out[label] = {
            "T (steps per episode)": steps,
            "gamma = 1 - 1/T": gamma,
            "return clip -1/(1-gamma)": -1.0 / (1.0 - gamma),
            "episodes per cycle": episodes_per_cycle(cfg),
            "env steps per cycle": env_steps,
            "updates per cycle": cfg.updates_per_cycle,
            "batch": batch,
            "updates per env step": cfg.updates_per_cycle / env_steps,
            "replayed transitions per env step": cfg.updates_per_cycle * batch / env_steps,
            "env steps per epoch": env_steps * cfg.cycles_per_epoch,
            "updates per epoch": cfg.updates_per_cycle * cfg.cycles_per_epoch,
        }
    return out


@dataclass
class PolicyEpisode:
    """One episode of a trained policy on the Franka task."""

    air_goal: bool
    success: bool
    clamped_steps: int
    grasped: bool
    cube_off_table: bool
    mean_gripper: float


def run_policy(env: FrankaPickPlaceEnv, policy, seed: int) -> PolicyEpisode:
    obs, _ = env.reset(seed=seed)
    box, info = env.layout.workspace, {}
    clamped, grasped, gripper = 0, False, []
    for _ in range(env.max_episode_steps):
        td = TensorDict(observation=torch.as_tensor(obs["observation"], dtype=torch.float32),
                        desired_goal=torch.as_tensor(obs["desired_goal"], dtype=torch.float32), batch_size=[])
        with torch.no_grad():
            action = policy(td)["action"].numpy()
        wanted = obs["observation"][OBS.gripper_position] + ACTION_SCALE * np.clip(action[:3], -1, 1)
        clamped += bool((wanted < np.array(box.low)).any() or (wanted > np.array(box.high)).any())
        gripper.append(float(action[3]))
        obs, _, _, _, info = env.step(action)
        lifted = obs["observation"][OBS.object_position][2] > env.layout.cube_centre_height + 0.02
        grasped = grasped or bool(lifted and (info["touch"] > 0).all())
    return PolicyEpisode(
        air_goal=bool(obs["desired_goal"][2] > env.layout.cube_centre_height + 0.001),
        success=bool(info["is_success"]),
        clamped_steps=clamped,
        grasped=grasped,
        cube_off_table=bool(obs["observation"][OBS.object_position][2] < env.layout.table_height),
        mean_gripper=float(np.mean(gripper)),
    )


def print_replay_lifts(run_dir: str) -> None:
    """Per epoch of a run's replay buffer (its checkpoint): how often exploration lifted the cube, and how high.

    Works for any pick-and-place run, Fetch or Franka: lifted is 2 cm above where the episode began. Episodes that
    began with the cube grasped (``env.grasped_start``: both pads on it at the first step) are counted apart.
    """
    state = load_checkpoint(run_dir)
    episodes, overwritten = stored_episodes(state)
    cfg = OmegaConf.create(state["config"])
    per_epoch = cfg.cycles_per_epoch * episodes_per_cycle(cfg)
    height = episodes["next", "achieved_goal"][..., 2] - episodes["achieved_goal"][:, :1, 2]
    began_grasped = (episodes["touch"][:, 0] > 0).all(-1)
    lifted = height > 0.02
    pinched = lifted & (episodes["next", "touch"] > 0).all(-1)
    print(f"\n-- exploration in {os.path.relpath(run_dir)}'s replay buffer ({len(episodes)} episodes, "
          f"{per_epoch} per epoch): of the episodes begun on the table, those that lifted the cube 2 cm, and with "
          "both pads touching it")
    # Epoch boundaries in the order collected; the oldest epoch may be partly overwritten.
    for first in range(-(overwritten % per_epoch), len(episodes), per_epoch):
        rows = slice(max(0, first), first + per_epoch)
        on_table = ~began_grasped[rows]
        highest = float(height[rows][on_table].max()) if on_table.any() else float("nan")
        print(f"  epoch {(overwritten + first) // per_epoch:3d}: lifted {fraction(lifted[rows][on_table].any(1).tolist())}, "
              f"both pads {fraction(pinched[rows][on_table].any(1).tolist())}, highest {highest * 100:.1f} cm; "
              f"{int(began_grasped[rows].sum())} more began grasped")


def fraction(flags) -> str:
    flags = list(flags)
    return f"{sum(flags)} of {len(flags)} ({sum(flags) / max(1, len(flags)):.2f})"


def table(rows: dict[str, dict[str, object]]) -> str:
    """Rows of ``{column: value}`` as aligned text, one column per key of the first row."""
    keys = list(next(iter(rows.values())))
    width = max(len(k) for k in keys) + 2
    header = "".ljust(width) + "".join(name[:42].ljust(44) for name in rows)
    lines = [header]
    for key in keys:
        cells = [rows[name][key] for name in rows]
        cells = [f"{c:.4g}" if isinstance(c, float) else str(c) for c in cells]
        lines.append(key.ljust(width) + "".join(c[:42].ljust(44) for c in cells))
    return "\n".join(line.rstrip() for line in lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--placements", type=int, default=50, help="cube placements for the scripted lift (default 50)")
    parser.add_argument("--shakes", type=int, default=20, help="grasps shaken by random full-speed moves (default 20)")
    parser.add_argument("--seed", type=int, default=1000, help="the first placement's seed (default 1000)")
    parser.add_argument("--grid", type=int, default=5, help="points per axis of the goal-space reach grid (default 5)")
    parser.add_argument("--policy", default=str(SHIPPED_POLICY),
                        help="a trained Franka policy file, or 'none' (default: the shipped one)")
    only = parser.add_mutually_exclusive_group()
    only.add_argument("--only-policy", action="store_true",
                      help="only the policy's figures, e.g. to follow a training run (--placements episodes)")
    only.add_argument("--replay", metavar="RUN_DIR",
                      help="only how often a run's exploration lifted the cube, per epoch (from its checkpoint)")
    args = parser.parse_args()
    if args.only_policy and args.policy == "none":
        parser.error("--only-policy needs a policy: --policy FILE (or the shipped one, the default)")
    if args.replay:
        print_replay_lifts(args.replay)
        return
    if args.only_policy:
        env = FrankaPickPlaceEnv()
        print_policy(args.policy, policy_episodes(env, args.policy, args.seed, args.placements), env.max_episode_steps)
        return
    start = time.perf_counter()
    envs = make_envs()
    franka = envs["franka"]
    layout: FrankaLayout = franka.layout

    print("physics: reading both models and grasping once each", flush=True)
    params = {name: physics(name, env) for name, env in envs.items()}
    grip = {name: widths(env) for name, env in envs.items()}

    lifts: dict[str, list[Lift]] = {}
    shakes: dict[str, list[bool]] = {}
    for name, env in envs.items():
        print(f"grasp and lift: {name}, {args.placements} placements to the highest goals", flush=True)
        lifts[name] = [lift_to_highest_goal(env, args.seed + k) for k in range(args.placements)]
        print(f"shaken grasps: {name}, {args.shakes} grasps", flush=True)
        shakes[name] = [shaken_and_held(env, args.seed + k) for k in range(args.shakes)]

    print("reach", flush=True)
    centre, r = np.asarray(layout.table_centre), layout.target_range
    axis = np.linspace(-r, r, args.grid)
    goal_space = reach_grid(franka, centre[0] + axis, centre[1] + axis,
                            np.linspace(layout.cube_centre_height, highest_goal_z(franka), args.grid), "goal space")
    # Below the grip height of a cube on the table the fingertips press on the table, which is no test of reach.
    low, high = (*layout.workspace.low[:2], layout.cube_centre_height), layout.workspace.high
    box = reach_grid(franka, *(np.linspace(a, b, 3) for a, b in zip(low, high)), "workspace box, 3 x 3 x 3")
    bare = FrankaPickPlaceEnv(layout=FrankaLayout(workspace=Workspace((-np.inf,) * 3, (np.inf,) * 3)))
    arm = reach_grid(bare, (0.3, 0.5, 0.6, 0.65, 0.7, 0.75, 0.8), (-0.3, 0.0, 0.3), (low[2], 0.25, 0.4, high[2]),
                     "the bare arm (no box), out to the Sim2Real loop's former box")

    print("schedule: composing torchrl_cebp/conf/", flush=True)
    schedule = schedules()

    episodes = [] if args.policy == "none" else policy_episodes(franka, args.policy, args.seed, args.placements)

    print(f"\n======== figures ({time.perf_counter() - start:.0f} s) ========")
    print("\n-- physics: Franka against Fetch PickAndPlace")
    print(table({name: params[name] for name in envs}))
    print("\n-- scripted grasp and lift to the highest goals, at top speed (action magnitude 1)")
    for name, runs in lifts.items():
        firsts = [run.first_success for run in runs if run.first_success is not None]
        print(f"  {name}: goal reached at the episode's end {fraction(r.success for r in runs)}; "
              f"cube left the fingers while carried {fraction(r.dropped for r in runs)}; "
              f"largest grip-to-cube offset carried {max(r.max_offset for r in runs) * 100:.1f} cm; "
              f"steps to the goal median {np.median(firsts) if firsts else float('nan'):.0f}, "
              f"max {max(firsts) if firsts else float('nan')} of {envs[name].max_episode_steps}")
    print("\n-- grasped cubes shaken by 30 steps of random full-speed moves")
    for name, held in shakes.items():
        print(f"  {name}: still between the fingers {fraction(held)}")
    print("\n-- what the observation says about the grip (gripper opening = sum of the finger positions)")
    for name, values in grip.items():
        print(f"  {name}: " + ", ".join(f"{k} {v * 100:.1f} cm" for k, v in values.items()))
    print(f"  fields (both, {OBS.size}): " + ", ".join(f"{n}[{s}]" for n, s in OBS.fields))
    print("\n-- reach with the hand pointing down (reached: within 5 mm, tilted < 3 deg, still)")
    for label, points in (("goal space", goal_space), ("workspace box", box), ("bare arm", arm)):
        missed = [p for p in points if not p.reached and not p.blocked]
        blocked = [p for p in points if not p.reached and p.blocked]
        print(f"  {label}: reached {fraction(p.reached for p in points)}, blocked by the cube {len(blocked)}, "
              f"smallest joint-limit margin {min(p.joint_margin for p in points):.2f} rad")
        for p in missed:
            print(f"    unreachable {tuple(round(v, 3) for v in p.target)}: off by {p.error * 100:.1f} cm, "
                  f"tilted {p.tilt_deg:.0f} deg, swinging {p.swing * 100:.1f} cm, joint margin {p.joint_margin:.2f}")
    print("\n-- training schedule (torchrl_cebp/conf/config.yaml + preset/paper.yaml)")
    print(table(schedule))
    if episodes:
        print_policy(args.policy, episodes, franka.max_episode_steps)


def policy_episodes(env: FrankaPickPlaceEnv, source: str, seed: int, episodes: int) -> list[PolicyEpisode]:
    """``episodes`` episodes of the policy in ``source`` on ``env`` (the loop's 100 steps), placed by ``seed + k``."""
    print(f"policy: {os.path.relpath(source)}, {episodes} episodes", flush=True)
    policy = load_policy(source)
    return [run_policy(env, policy, seed + k) for k in range(episodes)]


def print_policy(source: str, episodes: list[PolicyEpisode], episode_steps: int) -> None:
    """The policy's figures: success and grasps on table and air goals, moves out of the box, the gripper."""
    air = [e for e in episodes if e.air_goal]
    ground = [e for e in episodes if not e.air_goal]
    print(f"\n-- policy {os.path.relpath(source)}")
    print(f"  success: table goals {fraction(e.success for e in ground)}, "
          f"air goals {fraction(e.success for e in air)}")
    print(f"  grasped and lifted the cube (both pads touching, 2 cm up): table goals "
          f"{fraction(e.grasped for e in ground)}, air goals {fraction(e.grasped for e in air)}")
    print(f"  episodes commanding a move out of the workspace box "
          f"{fraction(e.clamped_steps > 0 for e in episodes)}, "
          f"steps {sum(e.clamped_steps for e in episodes)} of {len(episodes) * episode_steps}")
    print(f"  cube knocked off the table {fraction(e.cube_off_table for e in episodes)}; mean gripper action "
          f"{np.mean([e.mean_gripper for e in episodes]):+.2f} (-1 closes, +1 opens)")


if __name__ == "__main__":
    main()
