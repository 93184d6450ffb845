"""What the command line writes: `tasks` as an aligned table with each task's variation axes, help text as written
(no markup eaten, no type on an on/off flag), a closed pipe ending a command quietly, and long lines kept whole in
files."""

from __future__ import annotations

import io
import sys

import pytest
from typer.testing import CliRunner

from lano3dp.cli import app, console


def test_tasks_lists_every_task_with_its_variation_axes_in_aligned_columns():
    from lano3dp.sim.tasks import TASKS

    lines = CliRunner().invoke(app, ["tasks"]).output.splitlines()
    header, rows = lines[0], {line.split()[0]: line for line in lines[1:len(TASKS) + 1]}
    assert header.split()[:4] == ["task", "object", "slots", "variations"] and sorted(rows) == sorted(TASKS)
    column = header.index("variations")
    axes = {task: line[column:].split()[0].split(",") for task, line in rows.items()}
    assert axes["bowl_pour"] == ["clutter", "similar", "instance", "camera", "background", "obstacle"]
    assert "similar" not in axes["open_drawer"]  # it has no look-alike slots: "similar" changes nothing there
    assert all(line[header.index("instruction"):].startswith(TASKS[task].instruction) for task, line in rows.items())
    assert "obstacle:moving" in lines[-1]


def test_help_keeps_square_brackets_and_gives_no_type_to_on_off_flags():
    runner = CliRunner()
    plan_help = runner.invoke(app, ["plan", "--help"]).output
    assert "lano3dp[embeddings]" in " ".join(plan_help.split())  # rich markup used to swallow "[embeddings]"
    for command in ("eval", "train", "plan"):
        text = runner.invoke(app, [command, "--help"]).output
        assert "<bool>" not in text and "--help" in text
    assert "--ema" in runner.invoke(app, ["train", "--help"], terminal_width=120).output
    # the help keeps its panels: the basic options first, then the others by what they change
    eval_help = runner.invoke(app, ["eval", "--help"], terminal_width=120).output
    assert eval_help.index("Options") < eval_help.index("Settings") < eval_help.index("Perception") \
        < eval_help.index("Advanced")


class ClosedPipe(io.TextIOBase):
    """stdout after the reader went away (`lano3dp train --help | head`)."""

    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        raise BrokenPipeError(32, "Broken pipe")


def test_a_closed_pipe_ends_a_command_with_no_error_message(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    with pytest.raises(SystemExit) as ended:
        app(["tasks"], prog_name="lano3dp")
    assert ended.value.code == 1
    assert capsys.readouterr().err == ""  # before: "error: [Errno 32] Broken pipe"


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_the_console_wraps_long_lines_on_a_terminal_only(monkeypatch):
    line = "guided: failure after 130 steps, obstacle contact: no, " * 4
    for stream, lines in ((io.StringIO(), 1), (Terminal(), 3)):
        monkeypatch.setattr(sys, "stdout", stream)
        output = console()
        output.width = 80  # a terminal of 80 columns; a file has no width of its own
        output.print(line.strip())
        assert len(stream.getvalue().splitlines()) == lines


@pytest.fixture
def recorded(monkeypatch):
    """evaluate and run_instruction replaced by recorders of the config and the command line they were given."""
    import lano3dp.evaluation as evaluation

    calls = []

    def record(config, *args, command=None, **kwargs):
        calls.append((config, command))
        return {"summary": {"success_rate": 0.0, "successes": 0, "episodes": 0, "collision_rate": 0.0,
                            "mean_min_clearance": None, "mean_path_length": 0.0, "latency_mean_s": None,
                            "errors": []}, "timing": {"resumed_episodes": 0}, "notes": [], "scenes": [{"seed": 0}]}

    monkeypatch.setattr(evaluation, "evaluate", record)
    monkeypatch.setattr(evaluation, "run_instruction", record)
    return calls


def test_a_result_records_the_command_as_typed_without_the_click_package(recorded, monkeypatch, tmp_path):
    # `pip install -e .` brings typer, which carries its own copy of click; the click package comes only with extras
    monkeypatch.setitem(sys.modules, "click", None)
    result = CliRunner().invoke(app, ["run", "put the block in the drawer", "--scenes", "2", "--compare",
                                      "--out", str(tmp_path / "run")])
    assert result.exit_code == 0, result.output
    (_, command), = recorded
    assert command == f"lano3dp run 'put the block in the drawer' --scenes 2 --compare --out {tmp_path / 'run'}"


def test_re_running_a_results_file_never_writes_over_it(recorded, tmp_path):
    import json

    finished = tmp_path / "results.json"
    config = {"task": "bowl_pour", "episodes": 3, "out": str(finished)}
    finished.write_text(json.dumps({"schema": "lano3dp-results/1", "provenance": {}, "config": config}))
    before = finished.read_text()
    result = CliRunner().invoke(app, ["eval", "--config", str(finished)])
    # refused, or written somewhere new: either way the finished result stays
    assert result.exit_code == 2 or [str(config.out) for config, _ in recorded] != [str(finished)], result.output
    assert finished.read_text() == before


def test_the_command_line_runs_torch_on_one_thread_unless_told_otherwise():
    import os
    import subprocess

    probe = ("import sys; from lano3dp.cli import main; sys.argv = ['lano3dp', 'tasks']\n"
             "try:\n    main()\nexcept SystemExit:\n    pass\nimport torch; print('threads', torch.get_num_threads())")
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    threads = [subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                              env=env | extra).stdout.split()[-1] for extra in ({}, {"OMP_NUM_THREADS": "2"})]
    assert threads == ["1", "2"]
