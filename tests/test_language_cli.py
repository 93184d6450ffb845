"""`lano3dp plan`: instruction in, plan JSON out; clear errors with exit code 2."""

import json

from typer.testing import CliRunner

from lano3dp.cli import app

runner = CliRunner()


def test_plan_prints_the_plan_as_json():
    result = runner.invoke(app, ["plan", "Pour the red bowl into the pan, avoiding the blue mug"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == {
        "skill": "bowl_pour",
        "targets": [
            {"name": "bowl", "color": "red", "size": None, "position": None},
            {"name": "pan", "color": None, "size": None, "position": None},
        ],
        "obstacles": [{"name": "mug", "color": "blue", "size": None, "position": None}],
        "warnings": [],
    }


def test_plan_checks_objects_against_the_scene():
    ok = runner.invoke(app, ["plan", "pour the bowl into the pot", "--objects", "red_bowl,frying_pan"])
    assert ok.exit_code == 0 and [t["name"] for t in json.loads(ok.stdout)["targets"]] == ["bowl", "pan"]
    bad = runner.invoke(app, ["plan", "pour the green bowl into the pan", "--objects", "red_bowl,pan"])
    assert bad.exit_code == 2
    assert "error: target 'green bowl' is not in the scene; the scene has: red_bowl, pan" in bad.stderr


def test_plan_reports_instructions_it_cannot_plan():
    result = runner.invoke(app, ["plan", "close the drawer"])
    assert result.exit_code == 2 and "cannot plan 'close the drawer': no skill fits" in result.stderr


def test_plan_schema_lists_the_skills():
    result = runner.invoke(app, ["plan", "--schema"])
    assert result.exit_code == 0
    properties = json.loads(result.stdout)["properties"]
    assert "bowl_pour" in properties["skill"]["anyOf"][0]["enum"] and "refusal" in properties


def test_plan_with_an_unreachable_llm_falls_back_and_says_so():
    result = runner.invoke(
        app, ["plan", "open the drawer", "--llm", "--base-url", "http://127.0.0.1:9/v1", "--timeout", "2"]
    )
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["skill"] == "open_drawer"
    assert "plan from: offline_fallback" in result.stderr and "APIConnectionError" in result.stderr
