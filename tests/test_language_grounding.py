"""Issue 34, item 3: grounding never puts one object in another's place."""

import json

import pytest
from typer.testing import CliRunner

from lano3dp import OfflineDecomposer
from lano3dp.cli import app
from lano3dp.language import TargetNotInSceneError, UnknownObjectError
from lano3dp.language.grounding import ground_plan

# a put_item_in_drawer demo scene as the simulator's frame names it (role "robot" left out by callers)
DRAWER_SCENE = {
    "drawer": {"kind": "drawer", "color": "brown", "size": "medium", "role": "target"},
    "block": {"kind": "block", "color": "blue", "size": "medium", "role": "target"},
    "obstacle_0": {"kind": "cylinder", "color": "grey", "size": "large", "role": "obstacle"},
}


@pytest.fixture(scope="module")
def decomposer():
    return OfflineDecomposer()


@pytest.mark.parametrize("said", ["teapot", "bowl", "red block", "cube"])
def test_a_target_the_scene_lacks_is_an_error_naming_it_and_what_the_scene_holds(decomposer, said):
    plan = decomposer.decompose(f"put the {said} in the drawer")
    with pytest.raises(TargetNotInSceneError) as missing:
        ground_plan(plan, DRAWER_SCENE, decomposer.registry, obstacle_stand_ins=True)
    assert str(missing.value).startswith(
        f"target '{said}' is not in the scene; the scene has: drawer (medium brown drawer), block (medium blue "
        "block), obstacle_0 (large grey cylinder)"
    )
    with pytest.raises(TargetNotInSceneError):
        decomposer.decompose(f"put the {said} in the drawer", DRAWER_SCENE)


def test_a_registered_synonym_of_the_same_slot_is_the_same_object_not_a_substitute(decomposer):
    plan = decomposer.decompose("pour the bowl into the skillet", ["dish", "frying_pan"])
    assert plan.target_phrases == ["dish", "pan"]  # the registry says a dish is the bowl slot's object
    # the item slot accepts any noun as said, so its slot word is no synonym of "teapot"
    assert decomposer.decompose("put the toy in the drawer", DRAWER_SCENE).target_phrases == ["block", "drawer"]


def test_a_compound_names_a_kind_of_its_last_noun(decomposer):
    # "phone charger" is the charger (the base slot's synonym), never the scene's phone
    plan = decomposer.decompose("put the phone on the phone charger", {"phone": {}, "base": {}})
    assert plan.target_phrases == ["phone", "base"]
    plan = decomposer.decompose("pour the mixing bowl into the pan", {"bowl": {}, "pan": {}})
    assert plan.target_phrases == ["mixing bowl", "pan"]


def test_an_obstacle_of_the_targets_kind_is_never_the_target_itself(decomposer):
    scene = {"bowl": {"role": "target"}, "pan": {"role": "target"}, "obstacle_0": {"kind": "cylinder",
                                                                                 "role": "obstacle"}}
    plan = decomposer.decompose("pour the mixing bowl into the pan, careful of the fruit bowl")
    with pytest.raises(UnknownObjectError, match="obstacle 'fruit bowl' is not in the scene"):
        ground_plan(plan, scene, decomposer.registry)  # the scene's one bowl is the target
    grounded = ground_plan(plan, scene, decomposer.registry, obstacle_stand_ins=True)
    assert (grounded.plan.target_phrases, grounded.obstacles) == (["mixing bowl", "pan"], ["obstacle_0"])
    assert grounded.notes[0] == "obstacle 'fruit bowl' is not the target of the same kind; the scene holds no other"


def test_the_user_may_map_a_phrase_explicitly(decomposer):
    plan = decomposer.decompose("put the teapot in the drawer")
    grounded = ground_plan(plan, DRAWER_SCENE, decomposer.registry, mapping={"teapot": "block"})
    assert grounded.plan.target_phrases == ["block", "drawer"]
    assert grounded.notes == ["'teapot' is mapped to the scene's 'block', as asked"]


def test_a_named_obstacle_stands_in_only_as_the_demo_scenes_obstacle_and_says_so(decomposer):
    plan = decomposer.decompose("put the block in the drawer and keep clear of the mug")
    grounded = ground_plan(plan, DRAWER_SCENE, decomposer.registry, obstacle_stand_ins=True)
    assert (grounded.plan.target_phrases, grounded.obstacles) == (["block", "drawer"], ["obstacle_0"])
    assert grounded.notes == [
        "'mug' not in the simulated scene; avoiding its obstacle object(s) obstacle_0 instead (the demo scenes' "
        "stand-in for a named obstacle)"
    ]
    with pytest.raises(UnknownObjectError, match="obstacle 'mug' is not in the scene"):
        ground_plan(plan, DRAWER_SCENE, decomposer.registry)  # no stand-ins outside the demo scenes


def test_run_with_a_target_absent_from_the_scene_exits_non_zero_and_does_nothing(tmp_path):
    """`lano3dp run "put the teapot in the drawer"` used to print the plan with the teapot and act on the block."""
    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", "put the teapot in the drawer", "--max-steps", "3", "--out", str(out)])
    assert result.exit_code == 1, result.output
    assert "target 'teapot' is not in the scene; the scene has: drawer (medium brown drawer), block (medium blue " \
           "block)" in " ".join(result.output.split())
    assert not (out / "run.json").exists() and not list(out.glob("video_*.mp4"))


def test_plan_with_objects_reports_a_missing_target_in_one_line():
    result = CliRunner().invoke(app, ["plan", "put the teapot in the drawer", "--objects", "block,drawer"])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [
        "error: target 'teapot' is not in the scene; the scene has: block, drawer (nothing was done; name one of "
        "those, or map the phrase to one explicitly)"
    ]
    assert json.loads(CliRunner().invoke(app, ["plan", "put the block in the drawer", "--objects", "block,drawer"])
                      .stdout)["targets"][0]["name"] == "block"


def test_run_acts_on_a_target_the_user_maps_explicitly_and_says_so(tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", "put the teapot in the drawer", "--map", "teapot=block",
                                      "--max-steps", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    record = json.loads((out / "run.json").read_text())
    assert record["scenes"][0]["targets"] == ["block", "drawer"]
    assert any("teapot" in note and "block" in note for note in record["notes"])
    bad = CliRunner().invoke(app, ["run", "put the teapot in the drawer", "--map", "teapot"])
    assert bad.exit_code == 2 and "PHRASE=OBJECT" in bad.output
