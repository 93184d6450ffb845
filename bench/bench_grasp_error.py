"""Where a policy closes the gripper, against where the scripted expert closes it in the same scene.

For each episode (clean scene, seed `--seed` + i): the expert's plan of the scene gives its first action
with the gripper command past half-closed; the policy's rollout gives its own first such action. The
difference is reported as position (cm) and yaw about the vertical, folded into [-90, 90) degrees since
a parallel gripper closing at yaw a or a + 180 is the same grasp. Both grasps are top-down in these tasks.

    OMP_NUM_THREADS=1 python bench/bench_grasp_error.py --task phone_on_base --episodes 20 \\
        [--checkpoint RUN] [--label shipped] [--out results/grasp_error.json]

Without --checkpoint the packaged policy of the task is measured. Results are appended (keyed by task and
label) to the JSON, whose "commands" list names what made each entry.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from lano3dp.evaluate import EpisodeRunner, EvalConfig  # noqa: E402
from lano3dp.policy.pretrained import packaged_checkpoint  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
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


def measure(task: str, checkpoint: str, episodes: int, first_seed: int) -> list[dict]:
    runner = EpisodeRunner(EvalConfig(checkpoint=checkpoint, task=task, episodes=1))
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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", required=True)
    parser.add_argument("--checkpoint", default=None, help="run or checkpoint folder (default: the packaged policy)")
    parser.add_argument("--label", default=None, help="name of this entry (default: the checkpoint's folder)")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1_000_000)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "grasp_error.json")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)

    checkpoint = args.checkpoint or str(packaged_checkpoint(args.task))
    label = args.label or ("packaged" if args.checkpoint is None else Path(args.checkpoint).name)
    rows = measure(args.task, checkpoint, args.episodes, args.seed)
    closed = [r for r in rows if r["closed"]]
    yaw = np.abs([r["yaw_error_deg"] for r in closed])
    distance = [float(np.linalg.norm(r["position_error_cm"])) for r in closed]
    summary = {"episodes": len(rows), "closed": len(closed),
               "median_abs_yaw_error_deg": round(float(np.median(yaw)), 1) if closed else None,
               "share_within_15_deg": round(float(np.mean(yaw < 15)), 3) if closed else None,
               "median_position_error_cm": round(float(np.median(distance)), 1) if closed else None,
               "successes": sum(r["success"] for r in rows)}
    command = "OMP_NUM_THREADS=1 python bench/bench_grasp_error.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    results = json.loads(args.out.read_text()) if args.out.exists() else {"commands": [], "entries": {}}
    results["commands"] = [c for c in results["commands"] if c != command] + [command]
    results["entries"][f"{args.task}/{label}"] = {"summary": summary, "episodes": rows, "command": command}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".json.tmp")
    temporary.write_text(json.dumps(results, indent=2) + "\n")
    temporary.replace(args.out)  # atomic: a killed run leaves the previous file whole
    print(f"{args.task}/{label}: {json.dumps(summary)} -> {args.out}")


if __name__ == "__main__":
    main()
