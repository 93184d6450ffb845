"""The rule-based decomposer: instruction tables, obstacles, slot order, scene grounding, errors."""

from pathlib import Path

import pytest

from language_tables import score_table
from lano3dp.language import (
    InstructionNotUnderstoodError,
    OfflineDecomposer,
    SlotMismatchError,
    UnknownObjectError,
)
from lano3dp.language.registry import describe_scene

DATA = Path(__file__).parent / "data"


TABLES = {
    # table: (rows at least, exact plans measured before issue 34 at f126fbe / after, both under the one phrase
    # convention of tests/language_tables.py). instructions_heldout_2's one "before" miss that is now right is the
    # negated command it planned.
    "instructions.json": (40, 55, 55),
    "instructions_heldout.json": (30, 30, 30),
    "instructions_heldout_2.json": (60, 91, 94),
    "instructions_obstacles.json": (35, 73, 73),
}


@pytest.mark.parametrize("table", list(TABLES))
def test_instruction_tables_keep_their_exact_plan_rates_and_drop_no_obstacle(table):
    """Every earlier table at its rate or better; none drops a named obstacle, makes one a target, or plans a
    negated command. (The landmark rows of instructions_obstacles.json were re-expressed for the invariant.)"""
    rows, before, after = TABLES[table]
    score = score_table(DATA / table, OfflineDecomposer())
    print(f"\n{table}: {score.exact}/{score.total} exact (before issue 34: {before}); wrong: {score.wrong}")
    assert score.total >= rows
    assert score.exact >= after >= before, score.wrong
    assert (score.dropped_obstacles, score.obstacle_as_target, score.negated_planned) == ([], [], [])


def test_blind_table_3_plans_exactly_and_safely():
    """170 instructions written blind for issue 34 (tests/data/instructions_blind_3.README.txt), 50 must-refuse.
    At f126fbe: 95/170 exact (tests/data/score_blind.py), 39 of 70 named obstacles dropped, 9 negated commands
    planned. First run of the new rules (held out): 150/170 with score_blind.py, 152/170 under the convention.
    After fixing the general classes that run showed (no longer held out): 170/170 under the convention."""
    score = score_table(DATA / "instructions_blind_3.json", OfflineDecomposer())
    print(f"\nblind table 3: {score.exact}/{score.total} exact; wrong: {score.wrong}")
    assert (score.total, score.refusals_expected) == (170, 50)
    assert (score.dropped_obstacles, score.obstacle_as_target, score.negated_planned) == ([], [], [])
    assert score.exact >= 170, score.wrong


@pytest.mark.parametrize(("table", "rows", "refusals", "exact"), [
    # first runs, held out (tests/data/score_blind.py): table 4 105/120, table 5 102/120; these are the rates after
    # fixing the general classes each showed, under the phrase convention (docs/language.md)
    ("instructions_blind_4.json", 120, 35, 120),
    ("instructions_blind_5.json", 120, 37, 120),
    ("instructions_blind_6.json", 120, 36, 120),  # first run 103/120 (score_blind.py), 108/120 (convention)
    ("instructions_blind_7.json", 120, 38, 117),  # first run 98/120 (both scorers)
    ("instructions_blind_8.json", 120, 41, 114),  # first run 79/120 (score_blind.py), 82/120 (convention)
    ("instructions_blind_9.json", 120, 38, 108),  # first run 75/120 (score_blind.py), 77/120 (convention)
    ("instructions_blind_10.json", 120, 38, 120),  # first run 113/120 (score_blind.py), 115/120 (convention)
    ("instructions_blind_11.json", 143, 43, 143),  # first run 132/143 (score_blind.py), 137/143 (convention)
    ("instructions_blind_12.json", 149, 45, 148),  # first run 133/149 (score_blind.py), 140/149 (convention)
    ("instructions_blind_13.json", 146, 42, 146),  # first run 133/146 (score_blind.py), 134/146 (convention)
    ("instructions_blind_14.json", 145, 43, 144),  # first run 130/145 (score_blind.py), 134/145 (convention)
    ("instructions_blind_15.json", 145, 42, 144),  # first run 138/145 (score_blind.py), 140/145 (convention)
    ("instructions_blind_16.json", 151, 41, 148),  # first run 135/151 (score_blind.py), 139/151 (convention)
    ("instructions_blind_17.json", 155, 42, 155),  # first run 141/155 (score_blind.py), 145/155 (convention)
    ("instructions_blind_18.json", 155, 42, 154),  # first run 145/155 (score_blind.py), 150/155 (convention)
    ("instructions_blind_19.json", 156, 43, 156),  # first run 145/156 (score_blind.py), 149/156 (convention)
    ("instructions_blind_20.json", 178, 51, 176),  # first run 139/178 (score_blind.py), 146/178 (convention)
    ("instructions_blind_21.json", 173, 48, 172),  # first run 141/173 (score_blind.py), 144/173 (convention)
    ("instructions_blind_22.json", 174, 48, 171),  # first run 162/174 (score_blind.py), 165/174 (convention)
    ("instructions_blind_23.json", 168, 52, 150),  # first run 129/168 (score_blind.py), 133/168 (convention)
    ("instructions_blind_24.json", 169, 46, 167),  # first run 160/169 (score_blind.py), 164/169 (convention)
    ("instructions_blind_25.json", 172, 46, 171),  # first run 163/172 (score_blind.py), 166/172 (convention)
    ("instructions_blind_26.json", 186, 53, 184),  # first run 171/186 (score_blind.py), 176/186 (convention)
    ("instructions_blind_27.json", 153, 46, 149),  # first run 144/153 (score_blind.py), 148/153 (convention)
    ("instructions_blind_28.json", 195, 50, 191),  # first run 180/195 (score_blind.py), 185/195 (convention)
    ("instructions_blind_29.json", 191, 49, 190),  # first run 182/191 (score_blind.py), 186/191 (convention)
    ("instructions_blind_30.json", 182, 53, 181),  # first run 173/182 (score_blind.py), 177/182 (convention)
    ("instructions_blind_31.json", 177, 49, 175),  # first run 167/177 (score_blind.py), 172/177 (convention)
    ("instructions_blind_32.json", 170, 48, 170),  # first run 165/170 (score_blind.py), 167/170 (convention)
    ("instructions_blind_33.json", 179, 48, 176),  # first run 167/179 (score_blind.py), 171/179 (convention)
    ("instructions_blind_34.json", 179, 48, 178),  # first run 169/179 (score_blind.py), 172/179 (convention)
    ("instructions_blind_35.json", 180, 48, 172),  # first run 157/180 (score_blind.py), 162/180 (convention)
    ("instructions_blind_36.json", 180, 49, 167),  # first run 153/180 (score_blind.py), 159/180 (convention)
    ("instructions_blind_37.json", 178, 49, 176),  # first run 166/178 (score_blind.py), 170/178 (convention)
    ("instructions_blind_38.json", 178, 49, 178),  # first run 169/178 (score_blind.py), 175/178 (convention)
    ("instructions_blind_39.json", 178, 49, 177),  # first run 174/178 (score_blind.py), 177/178 (convention)
])  # fmt: skip
def test_later_blind_tables_keep_their_rates_and_stay_safe(table, rows, refusals, exact):
    score = score_table(DATA / table, OfflineDecomposer())
    print(f"\n{table}: {score.exact}/{score.total} exact; wrong: {score.wrong}")
    assert (score.total, score.refusals_expected) == (rows, refusals)
    assert set(score.dropped_obstacles) <= CONTESTED.get(table, set())
    assert (score.obstacle_as_target, score.negated_planned) == ([], [])
    assert score.exact >= exact, score.wrong


# Rows whose author expects an obstacle the phrase convention reads otherwise (docs/language.md, "Contested rows");
# they still count as wrong in the rate.
CONTESTED = {
    # "the black one" after "the base" is read as a black base (avoided), the author meant a black phone
    "instructions_blind_27.json": {"put the phone on the base, not the black one"},
    # a shelf that objects stand on is a surface like the table, never avoided; the author avoided it
    "instructions_blind_35.json": {"mind the elves on the shelf and the five lenses, then put the phone on the dock"},
    # "dice" is kept as said, the word most people use for one die too; the author wrote its singular "die"
    "instructions_blind_36.json": {"pour the bowl into the pan, avoid the two red dice and the three blue dice"},
}


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
