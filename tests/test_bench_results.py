"""Results files: the bench contract's writer, the repository's results/ (provenance, pages, INDEX.md) and their
one-shot migration (`lano3dp migrate`)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench_loader import ROOT, load_bench
from lano3dp.migrate import migrate
from lano3dp.provenance import BEHAVIOUR_VERSION, RESULTS_SCHEMA

RESULTS = ROOT / "results"
contract = load_bench("_contract")
make_index = load_bench("make_index")


def test_index_md_is_current_with_the_results_json_files():
    """Fails when a results JSON was added, changed or removed without `python bench/make_index.py`."""
    assert (RESULTS / "INDEX.md").read_text() == make_index.render_index(RESULTS), \
        "results/INDEX.md is out of date: run python bench/make_index.py"


def test_every_results_json_carries_its_schema_kind_command_and_commit():
    files = sorted(RESULTS.glob("*.json"))
    assert len(files) >= 83
    for path in files:
        data = json.loads(path.read_text())
        made = data.get("provenance") or {}
        assert data.get("schema") == RESULTS_SCHEMA and data.get("kind"), path.name
        assert made.get("command"), f"{path.name} records no command"
        assert made.get("commit") or made.get("committed_in"), f"{path.name} records no commit"
        assert "behaviour_version" in made, path.name


def test_every_page_generated_from_a_json_names_it():
    pages = [page for page in sorted(RESULTS.glob("*.md")) if page.with_suffix(".json").exists()]
    assert len(pages) >= 68
    for page in pages:
        name = page.with_suffix(".json").name
        assert f"Generated from [`{name}`]({name})" in page.read_text(), page.name


def test_the_writer_records_provenance_generates_the_page_from_the_json_and_refreshes_the_index(tmp_path):
    parser = contract.bench_parser("bench/bench_demo.py", "Demo bench.\n\nMore.", tasks="bowl_pour", episodes=3,
                                   seed=7, workers=contract.Unused("one process"))
    parser.add_argument("--rho", type=float, default=0.04)
    args = contract.parse(parser, ["--tasks", "bowl_pour,open_drawer", "--seed", "100", "--out-dir", str(tmp_path),
                                   "--tag", "_x"])
    assert args.tasks == ["bowl_pour", "open_drawer"] and args.seed == 100 and args.episodes == 3
    path = contract.write_results("demo", args, {"rows": [1, 2]},
                                  markdown=lambda record: f"# Demo\n\nrows {record['rows']}\n")
    assert path == tmp_path / "demo_x.json"
    record = json.loads(path.read_text())
    assert record["schema"] == RESULTS_SCHEMA and record["kind"] == "demo" and record["rows"] == [1, 2]
    made = record["provenance"]
    assert made["command"] == f"python bench/bench_demo.py --tasks bowl_pour,open_drawer --seed 100 --out-dir " \
                              f"{tmp_path} --tag _x"
    assert made["behaviour_version"] == BEHAVIOUR_VERSION and made["config"]["rho"] == 0.04
    assert made["config"]["seed"] == 100 and "workers" not in made["config"]  # an unused argument is no setting
    page = path.with_suffix(".md").read_text()
    assert page.startswith("# Demo\n\nGenerated from [`demo_x.json`](demo_x.json), made by `python bench/bench_demo.py")
    assert page.endswith("rows [1, 2]\n")
    assert "| [demo_x.json](demo_x.json) ([page](demo_x.md)) | demo |" in (tmp_path / "INDEX.md").read_text()


def test_a_bench_records_the_commit_it_started_at_not_one_made_while_it_ran(tmp_path, monkeypatch):
    import subprocess

    from lano3dp import provenance

    head = {"commit": "a" * 40}

    def git(command, **kwargs):
        out = head["commit"] if "rev-parse" in command else ""
        return subprocess.CompletedProcess(command, 0, stdout=out, stderr="")

    monkeypatch.setattr(provenance.subprocess, "run", git)
    provenance.source_commit.cache_clear()
    try:
        parser = contract.bench_parser("bench/bench_demo.py", "Demo.", tasks="bowl_pour", episodes=1, seed=0)
        args = contract.parse(parser, ["--out-dir", str(tmp_path)])
        head["commit"] = "b" * 40  # a commit made while the bench runs
        record = json.loads(contract.write_results("demo", args, {"rows": []}).read_text())
    finally:
        provenance.source_commit.cache_clear()
    assert record["provenance"]["commit"] == "a" * 40


def test_the_seed_is_the_first_seed_and_an_unused_argument_is_refused_with_its_reason(capsys):
    parser = contract.bench_parser("bench/bench_demo.py", "Demo.", tasks=contract.Unused("no simulator task"),
                                   episodes=2, seed=0)
    with pytest.raises(SystemExit):
        contract.parse(parser, ["--tasks", "bowl_pour"])
    assert "--tasks does not apply to bench_demo.py: no simulator task" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        contract.parse(parser, ["--seed", "0,1"])  # a list is not a first seed
    defaults = contract.parse(parser, [])
    assert defaults.tasks is None and defaults.out_dir == RESULTS
    assert contract.arguments(defaults)["out_dir"] == "results"  # no machine path in a results file


def old_bench_results() -> dict:
    obstacle = {"shape": "Cylinder", "repr": "Cylinder(...)", "center": [0.4, 0.0], "radius": 0.03,
                "safety_distance": 0.12}
    return {"command": "OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --task bowl_pour --episodes 2",
            "when_utc": "2026-12-01T10:00:00Z", "task": "bowl_pour",
            "conditions": {"phantom": {"episodes_detail": [{"seed": 1, "obstacles": [obstacle]},
                                                           {"seed": 2, "obstacles": [{**obstacle, "kind": "box"}]}]}}}


def test_migrate_gives_an_earlier_bench_file_schema_kind_provenance_and_named_obstacle_shapes(tmp_path):
    path = tmp_path / "phantom_obstacle_bowl_pour.json"
    path.write_text(json.dumps(old_bench_results()))
    (changed,) = migrate([path])
    assert "1 obstacle descriptions given their shape's kind" in changed
    data = json.loads(path.read_text())
    assert data["schema"] == RESULTS_SCHEMA and data["kind"] == "phantom_obstacle" and "command" not in data
    made = data["provenance"]
    assert made["command"].startswith("OMP_NUM_THREADS=1 python bench/bench_phantom_obstacle.py --task bowl_pour")
    assert made["created_utc"] == "2026-12-01T10:00:00Z" and made["behaviour_version"] == 0
    assert made["commit"] is None and made["committed_in"] is None  # not in a git checkout here
    details = data["conditions"]["phantom"]["episodes_detail"]
    assert [d["obstacles"][0]["kind"] for d in details] == ["cylinder", "box"]  # a named shape stays as it was
    assert migrate([path]) == []  # current now: nothing more to convert


def test_migrate_collects_the_commands_of_a_file_that_gathers_several_runs(tmp_path):
    path = tmp_path / "heldout_x.json"
    path.write_text(json.dumps({"note": "n", "runs": {
        "a": {"command": "lano3dp eval --checkpoint a", "summary": {}},
        "b": {"command": "lano3dp eval --checkpoint b", "summary": {}}}}))
    migrate([path])
    data = json.loads(path.read_text())
    assert data["kind"] == "heldout"
    assert data["provenance"]["command"] == ["lano3dp eval --checkpoint a", "lano3dp eval --checkpoint b"]
    assert data["runs"]["a"]["command"] == "lano3dp eval --checkpoint a"  # the entries keep their own


def test_the_index_marks_a_migrated_file_by_the_commit_it_was_committed_in(tmp_path):
    made = {"command": "python bench/bench_sim.py", "commit": None, "committed_in": "0123456789abcdef",
            "committed_utc": "2026-11-22T06:02:37+00:00", "behaviour_version": 0}
    (tmp_path / "bench_sim.json").write_text(json.dumps({"schema": RESULTS_SCHEMA, "kind": "sim",
                                                         "provenance": made}))
    assert "| [bench_sim.json](bench_sim.json) | sim | `python bench/bench_sim.py` | committed in 0123456789 | " \
           "committed 2026-11-22 | 0 |" in make_index.render_index(Path(tmp_path))
