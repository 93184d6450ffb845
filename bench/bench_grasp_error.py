"""Where a policy closes the gripper, against where the scripted expert closes it in the same scene.

For each episode (clean scene, seed `--seed` + i): the expert's plan of the scene gives its first action
with the gripper command past half-closed; the policy's rollout gives its own first such action. The
difference is reported as position (cm) and yaw about the vertical, folded into [-90, 90) degrees since
a parallel gripper closing at yaw a or a + 180 is the same grasp. Both grasps are top-down in these tasks.

    OMP_NUM_THREADS=1 python bench/bench_grasp_error.py --tasks phone_on_base --episodes 20 \\
        [--policy pose_10min=bench/out/learning_pose/runs/phone_on_base_pose_seed0 --policy ...]

Without --policy the packaged policy of each task is measured (label "packaged"); with it, each LABEL=PATH of the
one task given. Writes <out-dir>/grasp_error<tag>.json, entries keyed "<task>/<label>".
"""

from __future__ import annotations

import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from _contract import Unused, bench_parser, parse, relative, write_results  # noqa: E402
from lano3dp.evaluation import EvalConfig  # noqa: E402
from lano3dp.evaluation.episodes import EpisodeRunner  # noqa: E402
from lano3dp.guidance.settings import guidance_preset  # noqa: E402

CLOSED = 0.5  # gripper command past which the fingers are closing


def yaw_of(action: np.ndarray) -> float:
    """Yaw (rad) of a top-down EE rotation from its 6D columns: the direction of the EE x axis."""
    return float(np.arctan2(action[4], action[3]))


def folded_degrees(angle: float) -> float:
    """An angle (rad) as degrees in [-90, 90): a grasp and the same grasp turned half a turn are one."""
    return float((np.degrees(angle) + 90.0) % 180.0 - 90.0)


def first_closing(actions: np.ndarray) -> int | None:
    closing = np.flatnonzero(actions[:, 9] > CLOSED)
    return int(closing[0]) if closing.size else None


def measure(task: str, checkpoint: str | None, episodes: int, first_seed: int) -> list[dict]:
    """Per episode: the policy's first closing action against the expert's, in the scene of that seed."""
    runner = EpisodeRunner(EvalConfig(checkpoint=checkpoint, task=task, episodes=1), guidance_preset("none"))
    env, executed = runner.env, []
    step = env.step

    def recording_step(action):
        executed.append(np.asarray(action, dtype=np.float64).copy())
        return step(action)

    env.step = recording_step
    rows = []
    for i in range(episodes):
        seed = first_seed + i
        env.reset(seed=seed)
        expert = env.expert_plan().actions()
        expert_close = expert[first_closing(expert)]
        executed.clear()
        result = runner.run(seed)
        policy_actions = np.array(executed)
        index = first_closing(policy_actions)
        row = {"seed": seed, "success": bool(result["success"]), "stage": result.get("stage"),
               "closed": index is not None}
        if index is not None:
            action = policy_actions[index]
            row.update(position_error_cm=[round(float(v), 2) for v in (action[:3] - expert_close[:3]) * 100],
                       yaw_error_deg=round(folded_degrees(yaw_of(action) - yaw_of(expert_close)), 1))
        rows.append(row)
        print(json.dumps(row), flush=True)
    runner.close()
    return rows


def summarize(rows: list[dict]) -> dict:
    closed = [r for r in rows if r["closed"]]
    yaw = np.abs([r["yaw_error_deg"] for r in closed])
    distance = [float(np.linalg.norm(r["position_error_cm"])) for r in closed]
    return {"episodes": len(rows), "closed": len(closed),
            "median_abs_yaw_error_deg": round(float(np.median(yaw)), 1) if closed else None,
            "share_within_15_deg": round(float(np.mean(yaw < 15)), 3) if closed else None,
            "median_position_error_cm": round(float(np.median(distance)), 1) if closed else None,
            "successes": sum(r["success"] for r in rows)}


def main(argv=None) -> dict:
    parser = bench_parser(__file__, __doc__, tasks="phone_on_base", episodes=20, seed=1_000_000,
                          workers=Unused("it replays the expert and the policy in this process, episode by episode"))
    parser.add_argument("--policy", action="append", default=[], metavar="LABEL=PATH",
                        help="a run or checkpoint folder of the one task given, and its label (repeatable; default: "
                             "the packaged policy, label packaged)")
    args = parse(parser, argv)
    torch.set_num_threads(1)
    if args.policy and len(args.tasks) != 1:
        parser.error("--policy names checkpoints of one task: give one task")
    policies = dict(item.split("=", 1) for item in args.policy) or {"packaged": None}
    entries = {}
    for task in args.tasks:
        for label, checkpoint in policies.items():
            rows = measure(task, checkpoint, args.episodes, args.seed)
            entries[f"{task}/{label}"] = {"checkpoint": relative(checkpoint) if checkpoint else f"packaged:{task}",
                                          "summary": summarize(rows), "episodes": rows}
            print(f"{task}/{label}: {json.dumps(entries[f'{task}/{label}']['summary'])}")
    print(write_results("grasp_error", args, {"entries": entries}))
    return entries


if __name__ == "__main__":
    main()
