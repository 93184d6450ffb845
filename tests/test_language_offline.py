"""The rule-based decomposer: instruction tables, obstacles, slot order, scene grounding, errors."""

import json
from pathlib import Path

import pytest

from lano3dp.language import (
    InstructionNotUnderstoodError,
    OfflineDecomposer,
    SlotMismatchError,
    UnknownObjectError,
)
from lano3dp.language.registry import describe_scene

DATA = Path(__file__).parent / "data"


def exact_plan_rate(path):
    cases = json.loads(path.read_text())["cases"]
    decomposer = OfflineDecomposer()
    failures = []
    for case in cases:
        try:
            plan = decomposer.decompose(case["instruction"], case.get("objects"))
            got = (plan.skill, plan.target_phrases, plan.obstacle_phrases)
        except Exception as error:  # a failure to plan counts as a wrong plan
            got = repr(error)
        if got != (case["skill"], case["targets"], case["obstacles"]):
            failures.append((case["instruction"], got))
    return 1 - len(failures) / len(cases), len(cases), failures


def test_instruction_table_exact_plan_rate():
    rate, count, failures = exact_plan_rate(DATA / "instructions.json")
    print(f"\noffline decomposer: {rate:.1%} exact plans on {count} instructions; failures: {failures}")
    assert count >= 40
    assert rate >= 0.90, failures


def test_held_out_instruction_table_exact_plan_rate():
    rate, count, failures = exact_plan_rate(DATA / "instructions_heldout.json")
    print(f"\noffline decomposer (held out): {rate:.1%} exact plans on {count} instructions; failures: {failures}")
    assert count >= 30
    assert rate >= 0.85, failures


def _object_words(ref: dict) -> frozenset:
    return frozenset(" ".join(str(ref.get(k) or "") for k in ("position", "size", "color", "name")).split())


def test_second_held_out_table_plans_exactly_and_never_drops_an_obstacle():
    """94 instructions written by someone who never read the rules (ObjectRef dicts; null = must be refused).

    Objects compare as word sets ('top drawer' == position 'top' + name 'drawer'), targets in slot order,
    obstacles as a multiset. Measured when the table arrived: 67% exact with 21 plans dropping a named
    obstacle (the rules before issue 16), then 97% with none.
    """
    from collections import Counter

    rows = json.loads((DATA / "instructions_heldout_2.json").read_text())
    decomposer = OfflineDecomposer()
    exact, wrong, dropped = 0, [], []
    for row in rows:
        try:
            plan = decomposer.decompose(row["instruction"]).model_dump()
        except Exception:  # a refusal
            plan = None
        expected = row["expected"]
        if expected is None or plan is None:
            ok = expected is None and plan is None
        else:
            def key(p):
                return (p["skill"], [_object_words(t) for t in p["targets"]],
                        Counter(_object_words(o) for o in p["obstacles"]))
            ok = key(plan) == key(expected)
            got = Counter(_object_words(o) for o in plan["obstacles"])
            if any(got[w] < n for w, n in Counter(_object_words(o) for o in expected["obstacles"]).items()):
                dropped.append(row["instruction"])
        exact += ok
        if not ok:
            wrong.append(row["instruction"])
    print(f"\nsecond held-out table: {exact}/{len(rows)} exact; wrong: {wrong}")
    assert len(rows) >= 60
    assert exact / len(rows) >= 0.95, wrong
    assert dropped == []


@pytest.fixture(scope="module")
def decomposer():
    return OfflineDecomposer()


def test_targets_follow_slot_order_not_mention_order(decomposer):
    plan = decomposer.decompose("Fill the skillet with what's in the green bowl")
    assert plan.skill == "bowl_pour" and plan.target_phrases == ["green bowl", "pan"]


def test_several_obstacles_with_colours_and_sizes(decomposer):
    plan = decomposer.decompose(
        "Avoid the big red mug, the glass and the small vase, then put the phone on the base without touching the lamp"
    )
    assert plan.skill == "phone_on_base" and plan.target_phrases == ["phone", "base"]
    assert plan.obstacle_phrases == ["large red mug", "glass", "small vase", "lamp"]


def test_obstacle_nouns_do_not_pick_the_skill(decomposer):
    plan = decomposer.decompose("Put the block in the drawer, keep clear of the bottle")
    assert plan.skill == "put_item_in_drawer" and plan.obstacle_phrases == ["bottle"]


def test_avoid_it_refers_to_the_object_named_before(decomposer):
    plan = decomposer.decompose("Pour the bowl in the pan. Careful, the kettle is hot, avoid it!")
    assert plan.target_phrases == ["bowl", "pan"] and plan.obstacle_phrases == ["kettle"]


def test_in_the_way_possessives_and_numerals(decomposer):
    plan = decomposer.decompose("Pour the bowl into the pan; the mug is in the way")
    assert plan.target_phrases == ["bowl", "pan"] and plan.obstacle_phrases == ["mug"]
    plan = decomposer.decompose("Could you put the block in the drawer? There's a lamp in the way.")
    assert plan.skill == "put_item_in_drawer" and plan.obstacle_phrases == ["lamp"]
    plan = decomposer.decompose("Move the bowl's contents into the pan without spilling")
    assert plan.skill == "bowl_pour" and plan.target_phrases == ["bowl", "pan"] and plan.obstacles == []
    assert decomposer.decompose("pour the bowl into the pan and avoid the two cups").obstacle_phrases == ["cup"]


def test_implied_objects_take_the_slot_word(decomposer):
    assert decomposer.decompose("Water the plant").target_phrases == ["watering can", "plant"]
    assert decomposer.decompose("Sweep the crumbs into the dustpan").target_phrases == ["broom", "dustpan"]


def test_any_item_fills_the_wildcard_slot(decomposer):
    plan = decomposer.decompose("Put the stapler in the drawer")
    assert plan.skill == "put_item_in_drawer" and plan.target_phrases == ["stapler", "drawer"]
    plan = decomposer.decompose("put the bottle in the drawer")
    assert plan.skill == "bottle_in_drawer"  # a dedicated skill beats the wildcard


def test_verb_and_objects_disambiguate_shared_verbs(decomposer):
    assert decomposer.decompose("Open the drawer").skill == "open_drawer"
    assert decomposer.decompose("Open the wine bottle").skill == "open_wine_bottle"
    assert decomposer.decompose("Set the bottle upright").skill == "bottle_upright"


def test_instructions_no_skill_can_do_are_errors_not_guesses(decomposer):
    with pytest.raises(InstructionNotUnderstoodError, match="no skill fits \\(verbs: close; objects: drawer\\)"):
        decomposer.decompose("Close the drawer")
    with pytest.raises(InstructionNotUnderstoodError, match="'open_drawer' and 'open_wine_bottle' equally"):
        decomposer.decompose("Open it")
    with pytest.raises(InstructionNotUnderstoodError, match="no skill fits"):
        decomposer.decompose("What a nice day")


def test_scene_vocabulary_grounds_synonyms_and_rejects_absent_objects(decomposer):
    plan = decomposer.decompose("pour the bowl into the pot", ["dish", "frying_pan"])
    assert plan.target_phrases == ["dish", "pan"]  # "bowl" resolved to the scene's dish via the slot synonyms
    with pytest.raises(
        UnknownObjectError, match="target 'green bowl' is not in the scene; the scene has: red_bowl, pan"
    ):
        decomposer.decompose("pour the green bowl into the pan", ["red_bowl", "pan"])
    with pytest.raises(UnknownObjectError, match="obstacle 'vase'"):
        decomposer.decompose("pour the bowl into the pan avoiding the vase", ["red_bowl", "pan"])


def test_plans_are_validated_against_the_registry(decomposer):
    plan = decomposer.decompose("Pour the bowl into the pan")
    assert decomposer.registry.validate(plan) is plan
    with pytest.raises(SlotMismatchError):
        decomposer.registry.validate(plan.model_copy(update={"targets": plan.targets[:1]}))


def test_scene_given_as_frame_attributes_knows_colours_names_do_not_spell(decomposer):
    scene = {
        "bowl": {"kind": "bowl", "color": "blue", "size": "medium", "role": "target"},
        "pan": {"kind": "pan", "color": "black", "size": "medium", "role": "target"},
        "distractor_mug_2": {"kind": "mug", "color": "white", "size": "medium", "role": "distractor"},
    }
    plan = decomposer.decompose("pour the blue bowl into the pan and avoid the white mug", scene)
    assert plan.target_phrases == ["blue bowl", "pan"] and plan.obstacle_phrases == ["white mug"]
    with pytest.raises(UnknownObjectError, match="target 'blue bowl' is not in the scene"):
        decomposer.decompose("pour the blue bowl into the pan and avoid the white mug", list(scene))  # names only
    described = ["bowl (medium blue bowl)", "pan (medium black pan)", "distractor_mug_2 (medium white mug)"]
    assert describe_scene(scene) == described


def test_the_registry_says_what_the_gripper_carries():
    from lano3dp.language import default_registry
    from lano3dp.language.registry import SkillSpec, Slot

    registry = default_registry()
    assert registry.get("bowl_pour").carried_slot == 0
    assert registry.get("put_item_in_drawer").carried_slot == 0
    for fixture_skill in ("open_drawer", "close_microwave", "open_wine_bottle"):
        assert registry.get(fixture_skill).carried_slot is None
    with pytest.raises(ValueError, match="at most one"):
        SkillSpec(
            name="juggle",
            description="d",
            verbs=("juggle",),
            slots=(Slot(word="ball", carried=True), Slot(word="club", carried=True)),
        )
