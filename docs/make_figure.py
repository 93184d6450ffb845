"""The README's picture: one real episode of the README's instruction, guided and unguided, in three panels.

    python docs/make_figure.py          # writes docs/images/first_contact.png (about 2-4 minutes on a CPU)

The scene is fixed by a rule, not by its outcome: the first scene from seed 1000000 of put_item_in_drawer (the
task the README's instruction plans) whose layout has room for an obstacle, the first of the README's main command
(`lano3dp run "..." --scenes 5 --compare`), whose videos and top view that command keeps. The script runs the
instruction in that one scene as `lano3dp run --compare` does (the packaged policy, guided as the policy was tuned:
the `tuned` preset, then the same scene without guidance) and draws

    1. the front camera's view at the first step;
    2. what the policy conditions on: the block's and the drawer's clouds (64 points each, world frame), and the
       obstacle's cloud, which never enters the policy and becomes the guidance cost instead;
    3. the two executed end-effector paths from above, with the fitted obstacle and its safety distance.

The outcomes are printed and written into the picture's titles, whatever they are.
"""

from __future__ import annotations

import io
import sys
import tempfile
from pathlib import Path

import numpy as np

from lano3dp import RunConfig, run_instruction

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "images" / "first_contact.png"
INSTRUCTION = "put the block in the drawer and keep clear of the mug"
TASK, FIRST_SEED = "put_item_in_drawer", 1_000_000
COLORS = {"guided": "tab:blue", "unguided": "tab:orange"}


def outcome(episode: dict) -> str:
    done = "success" if episode["success"] else "not done"
    touched = "touched the obstacle" if episode["collided"] else "no contact"
    return f"{done} in {episode['steps']} steps, {touched}"


def first_frame_clouds(seed: int, obstacles: list[str]):
    """The scene at its first step: the camera image (256 px) and the object clouds as the policy's runner makes
    them (its camera resolution, crop box and point count)."""
    from lano3dp.evaluation import PerceptionSettings, PolicyBundle
    from lano3dp.geometry.frame import observe
    from lano3dp.sim.env import TabletopEnv

    bundle = PolicyBundle.load(None, task=TASK)  # the packaged policy, as `run` loads it
    env = TabletopEnv(TASK, variation="obstacle", image_size=256)
    picture = observe(env, env.reset(seed=seed)[0])[0].rgb
    env.close()
    env = TabletopEnv(TASK, variation="obstacle", image_size=bundle.observation.image_size)
    frame = observe(env, env.reset(seed=seed)[0])[0]
    env.close()
    observer = bundle.observer(PerceptionSettings())  # the simulator's masks, the policy's points and crop box
    targets = observer.observe(frame, list(bundle.policy.config.object_names))
    return picture, targets, observer.observe_instances(frame, obstacles)


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from lano3dp.guidance.shapes import draw_obstacle

    with tempfile.TemporaryDirectory() as out:
        run = run_instruction(RunConfig(INSTRUCTION, scenes=1, compare=True, seed=FIRST_SEED, out=out))
    scene = run["scenes"][0]
    if run["task"] != TASK or scene["seed"] < FIRST_SEED:
        raise SystemExit(f"the instruction ran {run['task']} seed {scene['seed']}; this figure is made for {TASK}")
    episodes = {label: records[0] for label, records in run["episodes"].items()}
    picture, targets, obstacles = first_frame_clouds(scene["seed"], scene["obstacles"])

    fig = plt.figure(figsize=(13.5, 4.4), dpi=100)
    ax = fig.add_subplot(1, 3, 1)
    ax.imshow(picture)
    ax.set_axis_off()
    ax.set_title(f"'{INSTRUCTION}'\n{TASK}, scene {scene['seed']}, front camera", fontsize=9)

    ax = fig.add_subplot(1, 3, 2, projection="3d")
    for name, points in zip(targets.names, targets.points, strict=True):
        ax.scatter(*points.T, s=7, label=f"{name} (policy input)")
    for points in obstacles.points:
        ax.scatter(*points.T, s=7, color="grey", label="obstacle (guidance cost)")
    ax.view_init(elev=35, azim=-150)
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(f"what the policy sees: {targets.points.shape[1]} points per object", fontsize=9)

    ax = fig.add_subplot(1, 3, 3)
    for index, obstacle in enumerate(episodes["guided"]["obstacles"]):
        draw_obstacle(ax, obstacle, label="obstacle (fitted)" if index == 0 else None)
    for label, episode in episodes.items():
        path = np.asarray(episode["ee_path"])
        ax.plot(path[:, 0], path[:, 1], "-", color=COLORS[label], lw=1.6, label=f"{label}: {outcome(episode)}")
        ax.plot(*path[0, :2], "o", color=COLORS[label], ms=5)
        ax.plot(*path[-1, :2], "x", color=COLORS[label], ms=7, mew=2)
    for name, centre in episodes["guided"]["targets"].items():
        ax.plot(centre[0], centre[1], "s", color="black", ms=5)
        ax.annotate(name, centre[:2], textcoords="offset points", xytext=(5, 5), fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    # contact is measured on the hand's whole body and the held block, not on the path's centre line
    ax.set_title("end-effector paths from above (o start, x end);\n'touched': the hand or the block met the obstacle",
                 fontsize=9)
    fig.tight_layout()

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    # a 256-colour palette keeps the picture small enough for a README (under 300 KB)
    image = Image.open(buffer).convert("RGB").quantize(colors=256)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    image.save(OUT, optimize=True)
    for label, episode in episodes.items():
        print(f"{label}: {outcome(episode)}")
    print(f"wrote {OUT.relative_to(ROOT)} ({OUT.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
