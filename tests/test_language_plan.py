"""TaskPlan, its JSON schema, and validation against the skill registry."""

import pytest
from pydantic import ValidationError

from lano3dp.language import (
    ObjectRef,
    PlanReply,
    SkillRegistry,
    SlotMismatchError,
    TaskPlan,
    UnknownObjectError,
    UnknownSkillError,
    default_registry,
    plan_json_schema,
)


def plan(skill, targets, obstacles=()):
    return TaskPlan(
        skill=skill,
        targets=[ObjectRef(name=t) for t in targets],
        obstacles=[ObjectRef(name=o) for o in obstacles],
    )


def test_object_ref_phrase_is_size_colour_noun_normalised():
    ref = ObjectRef(name=" Watering_Can ", color="Green", size="small")
    assert ref.phrase == "small green watering can" and str(ref) == ref.phrase
    assert ObjectRef(name="bowl").phrase == "bowl"
    with pytest.raises(ValidationError):
        ObjectRef(name="")
    with pytest.raises(ValidationError):
        ObjectRef(name="bowl", material="glass")


def test_plan_round_trips_through_json():
    original = TaskPlan(
        skill="bowl_pour",
        targets=[ObjectRef(name="bowl", color="red"), ObjectRef(name="pan")],
        obstacles=[ObjectRef(name="mug", color="blue")],
    )
    assert TaskPlan.model_validate_json(original.model_dump_json()) == original
    assert original.summary() == "bowl_pour(red bowl, pan); avoid blue mug"


def test_json_schema_is_strict_enumerates_skills_and_can_refuse():
    schema = plan_json_schema(default_registry().names)
    skill = schema["properties"]["skill"]["anyOf"]
    assert skill[0]["enum"][:3] == ["bottle_in_drawer", "bottle_upright", "bowl_pour"] and skill[1] == {"type": "null"}
    assert schema["required"] == ["refusal", "skill", "targets", "obstacles"]
    assert schema["additionalProperties"] is False and "warnings" not in schema["properties"]
    ref = schema["$defs"]["ObjectRef"]
    assert ref["required"] == ["name", "color", "size", "position"] and ref["additionalProperties"] is False
    assert {"type": "null"} in ref["properties"]["color"]["anyOf"]
    # The export must not mutate pydantic's cached schema.
    assert "enum" not in TaskPlan.model_json_schema()["properties"]["skill"]


def test_a_reply_is_a_plan_or_an_explicit_refusal():
    reply = PlanReply(skill="open_drawer", targets=[ObjectRef(name="drawer", position="top")])
    assert reply.to_plan().summary() == "open_drawer(top drawer)"
    with pytest.raises(ValueError, match="refused: no skill makes coffee"):
        PlanReply(refusal="no skill makes coffee").to_plan()
    with pytest.raises(ValueError, match="neither a skill nor a refusal"):
        PlanReply().to_plan()


def test_position_words_are_part_of_the_phrase_and_warnings_travel_with_the_plan():
    ref = ObjectRef(name="bowl", color="red", size="small", position="Left")
    assert ref.phrase == "left small red bowl"
    plan = TaskPlan(skill="open_drawer", targets=[ObjectRef(name="drawer")], warnings=["'it' may mean a or b"])
    assert TaskPlan.model_validate_json(plan.model_dump_json()).warnings == ["'it' may mean a or b"]


def test_default_registry_covers_the_simulator_tasks_with_ordered_slots():
    registry = default_registry()
    assert len(registry) == 10
    assert registry.get("bowl_pour").slot_words == ("bowl", "pan")
    assert registry.get("water_plants").slot_words == ("watering can", "plant")
    assert registry.get("phone_on_base").slot_words == ("phone", "base")
    assert registry.get("put_item_in_drawer").slots[0].accepts_any
    assert all(skill.verbs and skill.description for skill in registry)


def test_valid_plans_pass_unchanged():
    registry = default_registry()
    good = plan("bottle_in_drawer", ["bottle", "drawer"], ["lamp"])
    assert registry.validate(good) is good
    assert registry.validate(plan("bowl_pour", ["dish", "skillet"]))  # synonyms fit their slots
    assert registry.validate(plan("bowl_pour", ["mug", "pan"]))  # an unseen instance in the bowl's slot


def test_unknown_skill_names_the_known_ones():
    known = "bottle_in_drawer, bottle_upright, bowl_pour"  # task_names() order
    with pytest.raises(UnknownSkillError, match=f"unknown skill 'make_coffee'; the registry has: {known}"):
        default_registry().validate(plan("make_coffee", ["mug"]))


def test_target_count_must_match_the_slots():
    with pytest.raises(SlotMismatchError, match=r"takes 2 target\(s\) in the order \(bowl, pan\), got 1: \(bowl\)"):
        default_registry().validate(plan("bowl_pour", ["bowl"]))


def test_targets_out_of_slot_order_are_rejected():
    with pytest.raises(SlotMismatchError, match="in the order \\(bowl, pan\\)"):
        default_registry().validate(plan("bowl_pour", ["pan", "bowl"]))


def test_scene_vocabulary_rejects_objects_that_are_not_there():
    registry = default_registry()
    scene = ["red_bowl", "pan", "blue_mug"]
    ok = TaskPlan(skill="bowl_pour", targets=[ObjectRef(name="bowl", color="red"), ObjectRef(name="pan")])
    assert registry.validate(ok, scene) is ok
    wrong_colour = TaskPlan(skill="bowl_pour", targets=[ObjectRef(name="bowl", color="green"), ObjectRef(name="pan")])
    with pytest.raises(UnknownObjectError, match="target 'green bowl' is not in the scene; the scene has: red_bowl"):
        registry.validate(wrong_colour, scene)
    with pytest.raises(UnknownObjectError, match="obstacle 'vase'"):
        registry.validate(plan("bowl_pour", ["bowl", "pan"], ["vase"]), scene)


def test_registry_round_trips_through_json_and_takes_checkpoints(tmp_path):
    registry = default_registry().with_checkpoint("bowl_pour", tmp_path / "bowl_pour")
    path = tmp_path / "skills.json"
    path.write_text(registry.to_json())
    loaded = SkillRegistry.load(path)
    assert loaded.names == registry.names
    assert loaded.get("bowl_pour").checkpoint == tmp_path / "bowl_pour"
    assert loaded.get("bowl_pour").slots == default_registry().get("bowl_pour").slots
    with pytest.raises(ValueError, match="registered twice"):
        SkillRegistry([registry.get("bowl_pour"), registry.get("bowl_pour")])
