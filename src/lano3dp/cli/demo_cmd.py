"""`lano3dp demo`: the whole method on one task, in minutes on a CPU, with a report.

Stages (each skipped when its output already exists, so a re-run continues):
    1. collect   scripted-expert demonstrations (no obstacles: the policy never sees one in training)
    2. train     a small object-centric diffusion policy for a budget of CPU time
    3. evaluate  closed loop: clean scenes; scenes with a novel obstacle on the path, without and with
                 the paper's cost guidance (A_0|k)
    4. report    report.md with a results table, a rates plot, a top-view plot of one episode with and
                 without guidance, and a video
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import typer

from lano3dp.cli import _options
from lano3dp.guidance.settings import SAFETY_MARGIN, GuidanceSettings


def register(app: typer.Typer) -> None:
    app.command("demo")(demo_command)


def demo_command(
    ctx: typer.Context,
    out: Path = typer.Option(Path("lano3dp_demo"), help="Output folder (re-running with it resumes)."),
    # A carry with room for an obstacle on its path (door and drawer handles are within reach of the start:
    # no obstacle fits there). bench_protocol: 0% clean success up to 1200 steps, 20% at 1600, 35% at 2000.
    task: str = typer.Option("put_item_in_drawer", help="Simulator task."),
    demos: int = typer.Option(40, min=2, help="Scripted-expert demonstrations to collect (the paper's 40)."),
    minutes: float = typer.Option(10.0, help="Training budget in CPU-minutes of this process (a busy machine "
                                            "stretches the wall time, not the training; a short timing probe "
                                            "sizes the LR schedule)."),
    steps: int = typer.Option(None, min=1, help="Train exactly this many steps instead of a time budget."),
    episodes: int = typer.Option(20, min=1, help="Evaluation episodes per condition."),
    guidance_preset: str = typer.Option("recommended", "--guidance-preset", metavar="NAME",
                                        help="Guidance of the guided condition: " + _options.PRESET_HELP),
    set_: list[str] = typer.Option(None, "--set", metavar="PATH=VALUE",
                                   help="Change a guidance setting of the guided condition, e.g. --set "
                                        "guidance.sampler.rho=0.02 (repeatable)."),
    points: int = typer.Option(64, min=16, help="Points per object cloud (the policy default: a training step "
                                                "costs a quarter of 128 points' with the rest of the recipe; "
                                                "bench/bench_policy.py)."),
    workers: int = typer.Option(2, min=1, help="Parallel evaluation processes."),
    seed: int = typer.Option(0, help="Seed of the collection and training."),
) -> None:
    """Collect, train, evaluate with and without a novel obstacle and guidance, and write a report."""
    from rich.console import Console

    from lano3dp.cli.eval_cmd import command_line
    from lano3dp.evaluation import GuidanceChoice, with_assignments

    _options.task_name(task)
    _options.output_path(out, folder=True)
    if minutes <= 0:
        raise typer.BadParameter(f"must be > 0, got {minutes}", param_hint="--minutes")
    data = with_assignments({"guidance": {"preset": guidance_preset}}, set_ or ())
    if set(data) != {"guidance"}:
        raise typer.BadParameter("the demo's --set changes guidance settings only (guidance.<section>.<field>)",
                                 param_hint="--set")
    guided = _options.build_config(GuidanceChoice, data["guidance"])
    if guided.preset == "none":
        raise typer.BadParameter("the demo compares guided with unguided episodes: name a guided preset",
                                 param_hint="--guidance-preset")
    console = Console()
    report = run_demo(command=command_line(ctx), out=out, task=task, demos=demos, minutes=minutes, steps=steps,
                      episodes=episodes, guided=guided, points=points, workers=workers, seed=seed, console=console)
    console.print(f"[bold green]report:[/bold green] {report}")


# Training steps (batch 64, the default recipe, 40 demonstrations) by which bench/bench_learning.py measured a
# task's success near its final value (results/learning_cut_at_success.json: put_item_in_drawer 50% at 3244
# steps, 90% at 4865; open_drawer 80% at 3572, 86% at 5357); a demo policy with fewer is called under-trained.
STEPS_TO_LEARN: dict[str, int] = {"put_item_in_drawer": 4500, "open_drawer": 3500}
DEFAULT_STEPS_TO_LEARN = 4000


def training_warnings(train_config: dict, checkpoint: Path) -> list[str]:
    """Plain sentences for a policy that got fewer steps than planned, or than its task needs."""
    from lano3dp.train import checkpoint_progress

    progress = checkpoint_progress(checkpoint)
    done, planned = int(progress.get("step", train_config["steps"])), int(train_config["steps"])
    task = (train_config.get("policy") or {}).get("extra", {}).get("task")
    needed = STEPS_TO_LEARN.get(task, DEFAULT_STEPS_TO_LEARN)
    warnings = []
    if done < planned:
        # the learning rate follows the CPU budget (train.training_progress), so it still reached 0: only the
        # step count fell short of the timing probe's plan
        warnings.append(f"**The training budget ran out at step {done} of {planned} planned** "
                        f"({progress.get('cpu_s', 0) / 60:.1f} CPU-min): steps cost more than the timing probe "
                        "measured (a busier machine); the learning rate still decayed to 0 at the budget's end.")
    if done < needed:
        warnings.append(f"**This policy is under-trained: {done} steps, where {task or 'this task'} needs about "
                        f"{needed}** (bench/bench_learning.py); give `--minutes` more CPU time for a policy worth "
                        "judging.")
    return [*(w + "\n" for w in warnings)]


CONDITIONS = (
    # name, variation, guided
    ("clean", "clean", False),
    ("obstacle, no guidance", "obstacle", False),
    ("obstacle, guidance", "obstacle", True),
)


def run_demo(*, out: Path, **options) -> Path:
    """The demo into `out`, which is locked: a second demo into the same folder is refused."""
    from lano3dp.locking import WriteLock

    with WriteLock(out):
        return _run_demo(out=out, **options)


def _run_demo(*, command: str, out: Path, task: str, demos: int, minutes: float, steps: int | None, episodes: int,
              guided, points: int, workers: int, seed: int, console) -> Path:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from lano3dp.evaluation import EvalConfig, GuidanceChoice
    from lano3dp.jsonio import write_json
    from lano3dp.pipeline import collect_stage, eval_stage, train_stage

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings_path = out / "timings.json"
    timings = json.loads(timings_path.read_text()) if timings_path.exists() else {}
    started = time.perf_counter()

    skipped = []  # stages (pipeline.*_stage) say "...; skipping" when their output is already there

    def log(message: str) -> None:
        if message.endswith("skipping"):
            skipped.append(message)
        console.print(f"[cyan]{time.perf_counter() - started:6.0f}s[/cyan] {message}")

    def timed(name: str, function):
        began, before = time.perf_counter(), len(skipped)
        value = function()
        elapsed = time.perf_counter() - began
        if len(skipped) == before or name not in timings:  # a skipped stage keeps the time it took when it ran
            timings[name] = round(elapsed, 1)
        write_json(timings_path, timings)
        return value

    console.rule(f"[bold]lano3dp demo: {task}[/bold]")
    log(f"1/4 collecting {demos} scripted-expert demonstrations of {task} (clean scenes, no obstacles)")
    data = timed("collect_s", lambda: collect_stage(task, demos, out / "data" / f"{task}.zarr", log=log, seed=seed,
                                                    n_points=points))

    budget = f"{steps} steps" if steps else f"{minutes:g} CPU-min"
    log(f"2/4 training a small object-centric diffusion policy ({budget})")
    checkpoint = timed("train_s", lambda: train_stage(data, out / "run", steps=steps, minutes=minutes, seed=seed,
                                                      log=log))

    for warning in training_warnings(json.loads((Path(checkpoint) / "train_config.json").read_text()),
                                     Path(checkpoint)):
        log("[yellow]" + warning.strip().replace("**", "") + "[/yellow]")
    log(f"3/4 evaluating {episodes} episodes per condition: " + "; ".join(c[0] for c in CONDITIONS))
    results = {}
    for name, variation, is_guided in CONDITIONS:
        slug = name.replace(", ", "_").replace(" ", "_")
        # obstacle conditions run only scenes with room for the obstacle, so every such episode has one
        config = EvalConfig(checkpoint=str(checkpoint), task=task, variation=variation, episodes=episodes,
                            guidance=guided if is_guided else GuidanceChoice("none"),
                            obstacle_scenes_only=variation == "obstacle", workers=workers,
                            video_dir=str(out / "videos" / slug) if variation == "obstacle" else None, n_videos=1,
                            out=str(out / "eval" / f"{slug}.json"))
        with Progress(TextColumn(f"  {name:<24}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      TextColumn("{task.fields[status]}"), console=console) as bar:
            handle = bar.add_task(name, total=episodes, status="")
            tally = {"success": 0, "collided": 0}

            def progress(done, total, record, bar=bar, handle=handle, tally=tally):
                tally["success"] += bool(record["success"])
                tally["collided"] += bool(record["collided"])
                bar.update(handle, completed=done,
                           status=f"success {tally['success']}/{done}, collided {tally['collided']}/{done}")

            results[name] = timed(f"eval_{slug}_s", lambda config=config, progress=progress: eval_stage(
                config, log=log, progress=progress, command=command))
        from lano3dp.cli.eval_cmd import summary_line

        log(f"   {name}: {summary_line(results[name]['summary'])}")

    log("4/4 writing the report")
    timings.pop("total_this_run_s", None)  # (written by earlier versions) stage times are what add up
    write_json(timings_path, timings)
    report = write_demo_report(out, task=task, checkpoint=Path(checkpoint), results=results, timings=timings,
                               command=command, guided=results["obstacle, guidance"]["guidance"])
    log(f"done in {time.perf_counter() - started:.0f} s")
    return report


def describe_guidance(settings: GuidanceSettings) -> str:
    """The guided condition's settings in words, for the report."""
    sampler, cost = settings.sampler, settings.cost
    push = ("m per guided step, pushed isotropically in metres" if cost.metric_push
            else "pushed in normalised action units, as the paper")
    words = [f"rho = {sampler.rho:g} {push}", f"S = {sampler.last_steps}",
             "on the densified path" if cost.densify > 1 else "on the waypoints"]
    if cost.anchored:
        words.append("from the hand's present position")
        if cost.push_turn:
            words.append(f"the push turned {cost.push_turn:g} degrees round each obstacle")
    if sampler.strategy != "always":
        words.append(f"sampling strategy {sampler.strategy}")
    if settings.execution.filters:
        words.append(f"chunk filters {', '.join(settings.execution.filters)}")
    return ", ".join(words)


def write_demo_report(out: Path, *, task: str, checkpoint: Path, results: dict, timings: dict, command: str,
                      guided: dict) -> Path:
    """report.md + rates.png + top_view.png from the evaluation results."""
    from safetensors import safe_open

    from lano3dp.cli.eval_cmd import stage_line
    from lano3dp.data.store import EpisodeStore
    from lano3dp.policy.modeling import load_config
    from lano3dp.report import centimetres, markdown_table, percent, plot_rates, plot_top_view, wilson_interval
    from lano3dp.train import checkpoint_progress

    # the report reads the checkpoint's files rather than rebuilding the model, so it can be re-made for any
    # checkpoint the evaluations used, even one an older version of the code wrote
    policy_config = load_config(checkpoint / "config.json")
    with safe_open(str(checkpoint / "model.safetensors"), "pt") as weights:
        parameters = sum(math.prod(weights.get_slice(name).get_shape())
                         for name in weights.keys() if not name.startswith("normalizer."))
    train_config = json.loads((checkpoint / "train_config.json").read_text())
    progress = checkpoint_progress(checkpoint)
    steps_done = int(progress.get("step", train_config["steps"]))
    cpu_minutes = float(progress.get("cpu_s", 0.0)) / 60
    store = EpisodeStore.open(train_config["data"])

    rows = []
    for name, result in results.items():
        s = result["summary"]
        low, high = wilson_interval(s["successes"], s["episodes"])
        rows.append([name, s["episodes"], f"{percent(s['success_rate'])} ({percent(low)}–{percent(high)})",
                     percent(s["collision_rate"]), s.get("mean_collision_steps"), percent(s["safe_success_rate"]),
                     centimetres(s["mean_min_clearance"]), f"{s['mean_path_length']:.2f} m",
                     f"{1000 * s['latency_mean_s']:.0f} ms" if s["latency_mean_s"] else None])
    plot_rates(out / "rates.png", [(name, r["summary"]) for name, r in results.items()],
               title=f"{task}: {store.n_episodes} demos, {steps_done} training steps")

    # one paired scene (same seed) with and without guidance: the first obstacle scene, a rule fixed before any
    # outcome is seen
    unguided_runs, guided_runs = results["obstacle, no guidance"]["episodes"], results["obstacle, guidance"]["episodes"]
    pick = (unguided_runs[0], guided_runs[0])
    runs = [(f"no guidance (seed {pick[0]['seed']}): " + ("collided" if pick[0]["collided"] else "no contact"),
             pick[0]["ee_path"]),
            ("guidance A_0|k: " + ("collided" if pick[1]["collided"] else "no contact"), pick[1]["ee_path"])]
    plot_top_view(out / "top_view.png", runs, obstacles=pick[1]["obstacles"] or pick[0]["obstacles"],
                  objects=pick[0].get("targets") or {}, title=f"{task}, novel obstacle: executed EE path, top view")
    videos = [e.get("video") for r in results.values() for e in r["episodes"] if e.get("video")]

    # a stage skipped on a re-run keeps the time it took when it ran, so the sum is the time of a fresh run
    timing_rows = [[k.removesuffix("_s").replace("_", " "), f"{v:.0f} s"] for k, v in timings.items()]
    timing_rows.append(["**all stages**", f"{sum(timings.values()) / 60:.1f} min"])
    lines = [
        f"# lano3dp demo: {task}",
        "",
        f"Made by `{command}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.",
        "",
        "A small Lan-o3dp policy (object clouds of the task's objects + robot state -> diffusion over EE actions) "
        f"trained on **{store.n_episodes} scripted demonstrations** of clean scenes, then run in closed loop on new "
        "scenes: clean ones, and ones with a **novel obstacle** on the expert's path (never seen in training), "
        "without and with the paper's cost guidance on A_0|k "
        f"({describe_guidance(GuidanceSettings.from_dict(guided))}; the obstacle is "
        "segmented and fitted with a vertical cylinder, which the hand and the carried object are kept "
        f"{100 * SAFETY_MARGIN:g} cm clear of).",
        "",
        f"Policy: {parameters / 1e6:.2f} M parameters, UNet {tuple(policy_config.down_dims)}, "
        f"{policy_config.n_points} points per object, obs {policy_config.n_obs_steps} steps, horizon "
        f"{policy_config.horizon}, {policy_config.n_action_steps} actions per chunk; trained "
        f"{steps_done} steps ({cpu_minutes:.1f} CPU-min) at batch {train_config['batch_size']}, "
        f"lr {train_config['lr']:g}; "
        f"sampling {policy_config.inference_scheduler.upper()}-{policy_config.num_inference_steps}.",
        "",
        "## Results",
        "",
        markdown_table(["condition", "episodes", "success (95% CI)", "obstacle contact", "contact steps / episode",
                        "success w/o contact",
                        "mean min clearance", "mean path", "latency / chunk"], rows),
        "",
        "Where episodes stopped (share of episodes reaching each stage of the task, in order):",
        "",
        *(f"- {name}: {stage_line(r['summary']).removeprefix('stages reached: ')}" for name, r in results.items()
          if r["summary"].get("stage_rates")),
        "",
        *training_warnings(train_config, checkpoint),
        "![rates](rates.png)",
        "",
        "![top view](top_view.png)",
        "",
        *(f"- video: [{Path(v).relative_to(out)}]({Path(v).relative_to(out)})" for v in videos),
        "",
        "Read with care: a policy trained for minutes on a CPU, and few episodes per condition (see the intervals). "
        "Contacts and clearances are the simulator's ground truth; latency includes perception and was measured "
        "with the evaluation workers sharing the CPU.",
        "",
        "## Time",
        "",
        markdown_table(["stage", "wall time"], timing_rows),
        "",
    ]
    report = out / "report.md"
    report.write_text("\n".join(lines))
    return report
