"""Issue 34, items 1 and 2: every object named is acted on or avoided; what cannot be accepted is refused with
its reason. Each class is one row with the exact plan, refusal or warning."""

import re

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from lano3dp import OfflineDecomposer
from lano3dp.language import (
    ContradictionError,
    InstructionNotUnderstoodError,
    NegatedCommandError,
    PlanValidationError,
    SeveralTasksError,
    UnknownVerbError,
)
from lano3dp.language.mentions import object_mentions
from lano3dp.language.offline import tokenize
from lano3dp.language.spelling import COMMON_WORDS
from lano3dp.vocabulary import singular


@pytest.fixture(scope="module")
def decomposer():
    return OfflineDecomposer()


def reading(decomposer, instruction):
    plan = decomposer.decompose(instruction)
    return plan.skill, plan.target_phrases, plan.obstacle_phrases


# ---- item 1: obstacles said in ways that name no cue verb ----------------------------------------------------


DECLARED = [
    # a property or a warning
    ("Put the bottle in the drawer, the glass is fragile", ("bottle_in_drawer", ["bottle", "drawer"], ["glass"])),
    ("The kettle is very hot; pour the bowl into the pan", ("bowl_pour", ["bowl", "pan"], ["kettle"])),
    ("Careful, there's a vase near the drawer. Open the drawer", ("open_drawer", ["drawer"], ["vase"])),
    # quantified and pronoun lists
    ("Put the block in the drawer; the mug, the cup and the vase are all in the way, don't touch any of them",
     ("put_item_in_drawer", ["block", "drawer"], ["mug", "cup", "vase"])),
    ("Open the drawer. The lamp and the jar are both in the way.", ("open_drawer", ["drawer"], ["lamp", "jar"])),
    # compounds that share a target's head, and "can" after a noun
    ("Put the bottle in the drawer and avoid the water bottle",
     ("bottle_in_drawer", ["bottle", "drawer"], ["water bottle"])),
    ("Put the block in the drawer and keep clear of the tin can",
     ("put_item_in_drawer", ["block", "drawer"], ["tin can"])),
    # an unknown object word before the target: the wildcard slot takes the object of the verb
    ("Put the block next to the teapot in the drawer", ("put_item_in_drawer", ["block", "drawer"], ["teapot"])),
    ("Put the stapler next to the teapot in the drawer",
     ("put_item_in_drawer", ["stapler", "drawer"], ["teapot"])),
    # a landmark, a context sentence and an object after a negated verb are still named objects
    ("Open the drawer under the microwave", ("open_drawer", ["drawer"], ["microwave"])),
    ("There's a bowl next to the drawer. Open the drawer.", ("open_drawer", ["drawer"], ["bowl"])),
    ("Don't open the drawer; pour the bowl into the pan", ("bowl_pour", ["bowl", "pan"], ["drawer"])),
    # found by the blind table 3 (general classes, not its sentences)
    ("Move the teapot past the block into the drawer", ("put_item_in_drawer", ["teapot", "drawer"], ["block"])),
    ("Past the mug and the jar, put the eraser into the drawer",
     ("put_item_in_drawer", ["eraser", "drawer"], ["mug", "jar"])),
    ("Put the red block, not the mug, into the drawer", ("put_item_in_drawer", ["red block", "drawer"], ["mug"])),
    ("Open the bottle; the lamp and the jar, steer clear of every one of them",
     ("open_wine_bottle", ["bottle"], ["lamp", "jar"])),
    ("Open the bottle but watch the teapot and the kettle, they're both hot",
     ("open_wine_bottle", ["bottle"], ["teapot", "kettle"])),
    ("Pour the bowl into the pan, careful with the pan lid", ("bowl_pour", ["bowl", "pan"], ["pan lid"])),
    ("Water the plant; the trash can is right behind it",
     ("water_plants", ["watering can", "plant"], ["trash can"])),
    ("Pour the bowl into the pan; keep the cutting board clear",
     ("bowl_pour", ["bowl", "pan"], ["cutting board"])),
    ("Put the sponge in the drawer, the laptop on the left is new",
     ("put_item_in_drawer", ["sponge", "drawer"], ["left laptop"])),
    ("Open the flask", ("open_wine_bottle", ["bottle"], [])),  # a registered synonym of the bottle in any skill
    # found by the blind table 5 (general classes, not its sentences)
    ("Open the drawer; the mugs are everywhere, careful of all of them", ("open_drawer", ["drawer"], ["mug"])),
    ("Put the block in the drawer, cups all over so be careful", ("put_item_in_drawer", ["block", "drawer"],
                                                                ["cup"])),
    ("Open the bottle that rolled over near the kettle", ("open_wine_bottle", ["bottle"], ["kettle"])),
    ("The thermos is hot, water the plant", ("water_plants", ["watering can", "plant"], ["thermos"])),
    ("Put the toy truck in the drawer", ("put_item_in_drawer", ["toy truck", "drawer"], [])),
    ("Place the toy train into the drawer, avoid the lamp", ("put_item_in_drawer", ["toy train", "drawer"],
                                                            ["lamp"])),
    ("Water the orchid", ("water_plants", ["watering can", "plant"], [])),  # a kind of the slot's object
    ("Water the plant, the cactus beside it is prickly", ("water_plants", ["watering can", "plant"], ["cactus"])),
    ("Pour the bowl into the pan, mind the adjacent kettle", ("bowl_pour", ["bowl", "pan"], ["kettle"])),
    ("Open the drawer, watch the lamp its new", ("open_drawer", ["drawer"], ["lamp"])),
    ("The stapler belongs in the drawer", ("put_item_in_drawer", ["stapler", "drawer"], [])),
    ("So the block goes into the drawer, avoid the mug", ("put_item_in_drawer", ["block", "drawer"], ["mug"])),
    ("Hi robot, would you mind closing the microwave", ("close_microwave", ["microwave"], [])),
    ("Set the phone onto the charging station", ("phone_on_base", ["phone", "base"], [])),
    ("Put the left block in the drawer, not the small one",
     ("put_item_in_drawer", ["left block", "drawer"], ["small block"])),
    # found by the blind table 6
    ("Close the microwave; the cup may be moved, the glass may not", ("close_microwave", ["microwave"], ["glass"])),
    ("The drawer's been pulled out halfway, open it fully", ("open_drawer", ["drawer"], [])),
    ("The phone has to go on the base, watch the lamp", ("phone_on_base", ["phone", "base"], ["lamp"])),
    ("Keep your hands off the kettle and close the microwave", ("close_microwave", ["microwave"], ["kettle"])),
    # a target named by a compound is reported as typed (tables 4-6: "mixing bowl", "kitchen drawer"); a noun that
    # can also be an adjective is a noun there, an adjective or participle describes and is dropped
    ("Pour the soup bowl into the pan", ("bowl_pour", ["soup bowl", "pan"], [])),
    ("Put the stapler in the office drawer", ("put_item_in_drawer", ["stapler", "office drawer"], [])),
    ("Put the key in the kitchen drawer", ("put_item_in_drawer", ["key", "kitchen drawer"], [])),  # not "wooden"
    ("Stand the juice bottle up, avoid the lamp", ("bottle_upright", ["juice bottle"], ["lamp"])),
    ("Water the tomato plant", ("water_plants", ["watering can", "tomato plant"], [])),
    ("Put the red toy block in the drawer", ("put_item_in_drawer", ["red toy block", "drawer"], [])),
    ("Put the phone on the phone charger", ("phone_on_base", ["phone", "phone charger"], [])),
    ("Open the wooden drawer", ("open_drawer", ["drawer"], [])),
    ("Stand the chipped bottle up", ("bottle_upright", ["bottle"], [])),
    ("Pour the bowl into the frying pan", ("bowl_pour", ["bowl", "pan"], [])),  # a registered synonym: slot word
    ("Pour the bowl into the pan, avoid the fruit bowl", ("bowl_pour", ["bowl", "pan"], ["fruit bowl"])),
    ("Put the big mixing bowl into the pan", ("bowl_pour", ["large mixing bowl", "pan"], [])),
    # a compound of another skill's object is one object wherever it stands: a landmark, a pronoun's referent
    ("Open the drawer beside the salad bowl", ("open_drawer", ["drawer"], ["salad bowl"])),
    ("There's a dog toy near the pan, stay clear of it. Pour the bowl into the pan",
     ("bowl_pour", ["bowl", "pan"], ["dog toy"])),
    # another skill's object said to be there, in the command's own sentence, is avoided, not refused
    ("There's a bowl by the drawer, so open the drawer gently", ("open_drawer", ["drawer"], ["bowl"])),
    ("Close the microwave, theres a phone next to it", ("close_microwave", ["microwave"], ["phone"])),
    ("A bottle is beside the pan, pour the bowl into the pan", ("bowl_pour", ["bowl", "pan"], ["bottle"])),
    # shorthand: a bare word that is also a verb names an object where it opens a clause and says where it is
    ("Put phone on base. Lamp nearby, careful", ("phone_on_base", ["phone", "base"], ["lamp"])),
    ("Open drawer. Cup on the left, careful", ("open_drawer", ["drawer"], ["cup"])),
    # a personal pronoun is never an object ("that" is a conjunction there)
    ("I want that you put the cube into drawer", ("put_item_in_drawer", ["cube", "drawer"], [])),
    # found by the blind table 7: no objects in times, in "'s" meaning "is", in what a broom sweeps, in a verb
    # after its subject, and "stays put" is no request to put anything
    ("Water the plant, it was dry all week", ("water_plants", ["watering can", "plant"], [])),
    ("Close the microwave, lunch's nearly done", ("close_microwave", ["microwave"], [])),
    ("Open the drawer, the lamp's fragile", ("open_drawer", ["drawer"], ["lamp"])),
    ("Sweep the rice into the dustpan, avoid the lamp", ("sweep_to_dustpan", ["broom", "dustpan"], ["lamp"])),
    ("Brush up the glitter into the dustpan", ("sweep_to_dustpan", ["broom", "dustpan"], [])),
    ("The astrolabe stays put; open the drawer", ("open_drawer", ["drawer"], ["astrolabe"])),
    ("Give the kettle a wide berth and close the microwave", ("close_microwave", ["microwave"], ["kettle"])),
    ("Open the drawer, keep off the toy trains", ("open_drawer", ["drawer"], ["toy train"])),  # once, not "toy" too
    # found by the blind table 11: irregular plurals from the lexicon, objects after a quantity and "of", a degree
    # before a state, a clause whose subject is "it", abstract nouns of idioms, adjectives that name a thing
    ("Close the microwave, mind the loaves", ("close_microwave", ["microwave"], ["loaf"])),
    ("Open the drawer, there are batteries and knives on the left", ("open_drawer", ["drawer"],
                                                                     ["battery", "knife"])),
    ("Open the drawer without hitting a pair of pliers or a bunch of widgets",
     ("open_drawer", ["drawer"], ["pliers", "widget"])),
    ("Loads of spanners are near the pan; pour the bowl into the pan", ("bowl_pour", ["bowl", "pan"], ["spanner"])),
    ("The microwave door is a tad wobbly, close the microwave", ("close_microwave", ["microwave"], [])),
    ("Open the drawer, it feels a little loose", ("open_drawer", ["drawer"], [])),
    ("Close the microwave and avoid the toaster, it was just used", ("close_microwave", ["microwave"],
                                                                      ["toaster"])),
    ("Put the phone on the base, that lamp cost me a fortune", ("phone_on_base", ["phone", "base"], ["lamp"])),
    ("Open the drawer, the iron is beside it", ("open_drawer", ["drawer"], ["iron"])),
    # found by the blind table 12: nouns joined to a noun phrase without their own determiner, every member of a
    # "there are" list, a position word said of the noun after it, the owner named after a possessive
    ("Open the drawer; the glasses and salt shakers must stay put", ("open_drawer", ["drawer"],
                                                                     ["glass", "salt shaker"])),
    ("Close the microwave, there are mugs, tea towels and toy trucks around, avoid them",
     ("close_microwave", ["microwave"], ["mug", "tea towel", "toy truck"])),
    ("Put the block in the middle drawer", ("put_item_in_drawer", ["block", "middle drawer"], [])),
    ("The lamp is my uncle's, so be careful with it and open the drawer", ("open_drawer", ["drawer"], ["lamp"])),
    # found by the blind table 13: the other place of a contrast, an unknown plural said to be there, a material
    # before the noun, a target's head said alone, a plural noun that is also a verb, a verb after its subject,
    # what the subject is said to be, a thing not wanted, a slot's compound synonym
    ("Put the phone on the white base, not on the black one", ("phone_on_base", ["phone", "white base"],
                                                               ["black base"])),
    ("Open the drawer, there are paintbrushes and rulers in front of it, avoid them",
     ("open_drawer", ["drawer"], ["paintbrush", "ruler"])),
    ("Close the microwave, careful of the porcelain teapot", ("close_microwave", ["microwave"], ["teapot"])),
    ("Water the plant with the watering can; the soldering iron is hot, keep the can away from it",
     ("water_plants", ["watering can", "plant"], ["soldering iron"])),
    ("Open the drawer and keep clear of the toy blocks", ("open_drawer", ["drawer"], ["toy block"])),
    ("Open the drawer, the mug blocks the way", ("open_drawer", ["drawer"], ["mug"])),
    ("That vase was a wedding present, so stay clear of it while you put the phone on the charger",
     ("phone_on_base", ["phone", "base"], ["vase"])),
    ("I don't want the red block, put the blue block in the drawer", ("put_item_in_drawer", ["blue block", "drawer"],
                                                                      ["red block"])),
    ("Sweep the dirt into the dustpan with the hand brush", ("sweep_to_dustpan", ["broom", "dustpan"], [])),
    # a side said with "-hand", a plural owner
    ("Open the left-hand drawer", ("open_drawer", ["left drawer"], [])),
    ("Pour the bowl into the pan, the kids' toys are everywhere", ("bowl_pour", ["bowl", "pan"], ["toy"])),
    # found by the blind table 14: an irregular participle before the noun, "that one" after the object was
    # avoided, "none of them", a side after the noun before a verb, "my work one", a state the object was left in
    ("Open the bottle, there's a lit candle just beside it", ("open_wine_bottle", ["bottle"], ["candle"])),
    ("Stand the green bottle upright. The brown bottle behind it is wobbly so don't touch that one",
     ("bottle_upright", ["green bottle"], ["brown bottle"])),
    ("Open the bottle. A glass and a candle are next to it, none of them can be knocked",
     ("open_wine_bottle", ["bottle"], ["glass", "candle"])),
    ("Pour the bowl into the pan. The red mug on the left stays untouched", ("bowl_pour", ["bowl", "pan"],
                                                                             ["left red mug"])),
    ("Water the plant and stay away from the laptop, it's my work one", ("water_plants", ["watering can", "plant"],
                                                                         ["laptop"])),
    ("Somebody left the microwave open again, close it please", ("close_microwave", ["microwave"], [])),
    # the table is no obstacle "them" can mean; "keep your distance from"
    ("Put the block in the drawer. My glasses are on the table, please don't break them",
     ("put_item_in_drawer", ["block", "drawer"], ["glass"])),
    ("Put the block in the drawer, keep a safe distance from the lamp", ("put_item_in_drawer", ["block", "drawer"],
                                                                         ["lamp"])),
    # what the user wants done to an object: "I want the drawer opened"
    ("I'd like the drawer opened", ("open_drawer", ["drawer"], [])),
    ("I need the microwave closed, mind the kettle", ("close_microwave", ["microwave"], ["kettle"])),
    # found by the blind table 15: "don't knock any", an unknown compound said to be there, "don't get it wet"
    ("Open the bottle, there are playing cards and chess pieces about so don't knock any",
     ("open_wine_bottle", ["bottle"], ["playing card", "chess piece"])),
    ("Water the plant on the left. The one on the right got water yesterday, so don't get it wet",
     ("water_plants", ["watering can", "left plant"], ["right plant"])),
    ("Water the plant but don't get the books wet", ("water_plants", ["watering can", "plant"], ["book"])),
    # what may happen is no request: "the water could spill"
    ("Sweep the crumbs into the dustpan, the cat bowl's water could spill",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["cat bowl"])),
    ("Put the block in the drawer and give the mug some space", ("put_item_in_drawer", ["block", "drawer"], ["mug"])),
    # found by the blind table 16: an agent noun heads its compound, "theres" without its apostrophe, units of a
    # substance, an object only said to be there weighs less than the task's own in choosing the skill
    ("Open the desk drawer, the paper shredder is next to it", ("open_drawer", ["desk drawer"], ["paper shredder"])),
    ("Put the bottle into the left drawer. theres a grey toy on the right, dont touch it",
     ("bottle_in_drawer", ["bottle", "left drawer"], ["right grey toy"])),
    ("Close the microwave, there are loaves of bread in front, go around them", ("close_microwave", ["microwave"],
                                                                                ["loaf"])),
    # a filler word after its article is a name the user gave; an unknown word alone after "the" is a noun
    ("Avoid the rofl and open the drawer", ("open_drawer", ["drawer"], ["rofl"])),
    ("Careful, there's a mug next to the drawer; put the babed in the drawer",
     ("put_item_in_drawer", ["babed", "drawer"], ["mug"])),
    # a side said of "the bottle of wine" and before a state; an owner and a person who did something earlier
    ("Open the bottle of wine on the left", ("open_wine_bottle", ["left bottle"], [])),
    ("Stand the bottle on the right upright", ("bottle_upright", ["right bottle"], [])),
    ("Sweep the dirt into the blue dustpan. The red dustpan belongs to my neighbour, keep off it.",
     ("sweep_to_dustpan", ["broom", "blue dustpan"], ["red dustpan"])),
    ("My son made a mess. Put the crayon in the drawer and go around the teddy bear",
     ("put_item_in_drawer", ["crayon", "drawer"], ["teddy bear"])),
    ("Put the block in the drawer, mind the baby", ("put_item_in_drawer", ["block", "drawer"], ["baby"])),
    ("Put the phone on the base, the cable can stay where it is", ("phone_on_base", ["phone", "base"], ["cable"])),
    # "one" is read before the mentions, so the contrasted object is named; "whichever" is a determiner
    ("Pour the red bowl into the pan, leave the green one", ("bowl_pour", ["red bowl", "pan"], ["green bowl"])),
    ("Pour whichever bowl is nearest into the pan", ("bowl_pour", ["bowl", "pan"], [])),
    # the robot's own body is no object; a verb with its particle after a noun names nothing
    ("Push the microwave door closed with your elbow", ("close_microwave", ["microwave"], [])),
    ("Close the microwave but watch out, the kettle's spout sticks out", ("close_microwave", ["microwave"],
                                                                         ["kettle"])),
    # found by the blind table 17: a lexicon verb or holder heading a compound, a state verb after the subject,
    # a participle after the noun, a number before it, where things stand ("crowded around", "sits between")
    ("Open the bottle, the chess set is laid out right next to it", ("open_wine_bottle", ["bottle"], ["chess set"])),
    ("The dustpan sits between the dog bed and the umbrella stand. Sweep the crumbs into the dustpan",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["dog bed", "umbrella stand"])),
    ("Put the phone on the base; the purple lamp at the back wobbles", ("phone_on_base", ["phone", "base"],
                                                                        ["back purple lamp"])),
    ("Open the bottle but mind the five wine glasses lined up behind it", ("open_wine_bottle", ["bottle"],
                                                                           ["wine glass"])),
    ("Three monitors are crowded around the microwave. Close the microwave without hitting any of them",
     ("close_microwave", ["microwave"], ["monitor"])),
    ("Dock the phone. Some loose screws are lying around, don't scatter them", ("phone_on_base", ["phone", "base"],
                                                                                ["screw"])),
    ("Slide the drawer out gently, the pill organiser sits right on top of it", ("open_drawer", ["drawer"],
                                                                                 ["pill organiser"])),
    ("Water the cactus. The frog can be touched, the wind chime can't", ("water_plants", ["watering can", "plant"],
                                                                          ["wind chime"])),
    ("pls water da plant, mind teh lamp", ("water_plants", ["watering can", "plant"], ["lamp"])),  # chat spellings
    # found by the blind table 19: the object "put" acts on is the one carried, never a bottle named beside it
    ("Put the sponge in the drawer next to the bottle", ("put_item_in_drawer", ["sponge", "drawer"], ["bottle"])),
    ("Put the sponge in the drawer, the bottle is next to it", ("put_item_in_drawer", ["sponge", "drawer"],
                                                                ["bottle"])),
    ("Can u close the microwave watch out for the mug", ("close_microwave", ["microwave"], ["mug"])),
    ("Open the wine bottle. My parents are coming over for dinner tonight.", ("open_wine_bottle", ["bottle"], [])),
    ("The bottle at the front fell over, please stand it upright", ("bottle_upright", ["front bottle"], [])),
    ("Sweep the flour into the dustpan, careful, the pink cake stand is wobbly",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["pink cake stand"])),
    ("Sweep the glitter into the dustpan with the push broom", ("sweep_to_dustpan", ["broom", "dustpan"], [])),
    # found by the blind table 18: where an object stands said after "is", a list after a permission, a room's
    # name before an unknown noun
    ("Sweep the crumbs into the dustpan. The laptop is on the left, stay clear of it",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["left laptop"])),
    ("The drawer is on the left, open it", ("open_drawer", ["left drawer"], [])),
    ("There's a mug on the left, open the drawer", ("open_drawer", ["drawer"], ["left mug"])),
    ("Close the microwave, the kitchen roll is leaning against it", ("close_microwave", ["microwave"],
                                                                     ["kitchen roll"])),
    ("I spilled some flour, can you sweep it into the dustpan? the flour jar is next to it",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["flour jar"])),  # what was spilled is the dirt swept
    # found by the blind table 20: dictated speech (fillers, words said twice, a phrase taken back without a
    # comma), owners and people, texting shorthand
    ("er close the the uh the microwave", ("close_microwave", ["microwave"], [])),
    ("put the blue block no sorry the red block in the drawer", ("put_item_in_drawer", ["red block", "drawer"], [])),
    ("stand up the small bottle wait no the big one", ("bottle_upright", ["large bottle"], [])),
    ("open the I mean close the microwave", ("close_microwave", ["microwave"], [])),
    ("pour the bowl into the pan, actually no, put the block in the drawer",
     ("put_item_in_drawer", ["block", "drawer"], [])),
    ("put the phone on the on the dock", ("phone_on_base", ["phone", "base"], [])),
    ("open the drawer, mind my aunt's teapot", ("open_drawer", ["drawer"], ["teapot"])),
    ("open the drawer, mind the kettle's spout", ("open_drawer", ["drawer"], ["kettle"])),
    ("could you close the microwave before my dad visits", ("close_microwave", ["microwave"], [])),
    ("the dog knocked the bottle over, stand it upright", ("bottle_upright", ["bottle"], [])),
    ("open the drawer, dont worry abt the sponge", ("open_drawer", ["drawer"], [])),
    ("put the block in the drawer, if you bump the cup thats fine", ("put_item_in_drawer", ["block", "drawer"], [])),
    # found by the blind table 21: technical wording, measures and materials before a noun
    ("Deposit the sponge in the left drawer.", ("put_item_in_drawer", ["sponge", "left drawer"], [])),
    ("Retrieve the phone and deposit it on the dock", ("phone_on_base", ["phone", "base"], [])),
    ("Kindly ensure the microwave is shut", ("close_microwave", ["microwave"], [])),
    ("make sure the bottom drawer is open", ("open_drawer", ["bottom drawer"], [])),
    ("please make sure the bottle is upright", ("bottle_upright", ["bottle"], [])),
    ("hydrate the plant with the watering can", ("water_plants", ["watering can", "plant"], [])),
    ("open the drawer, mind the 3 litre jug and the 250 ml glass flask", ("open_drawer", ["drawer"], ["jug", "flask"])),
    ("close the microwave, the cast-iron pot and the glass jar are fragile",
     ("close_microwave", ["microwave"], ["pot", "jar"])),
    ("open the drawer, mind the glass and the wine glass", ("open_drawer", ["drawer"], ["glass", "wine glass"])),
    # found after the first runs of tables 20 and 21 (no longer held out): a colour whose noun comes with the next
    # one, "the one" telling which, where things stand in a "there are" clause, events, vague words, openers
    ("Stand the blue bottle upright, leave the red and the green bottles alone",
     ("bottle_upright", ["blue bottle"], ["red bottle", "green bottle"])),
    ("there are cups and a teapot around the bowl, pour it into the pan", ("bowl_pour", ["bowl", "pan"],
                                                                             ["cup", "teapot"])),
    ("put the phone on the dock, the white one", ("phone_on_base", ["phone", "white base"], [])),
    ("open the drawer, the one on the right", ("open_drawer", ["right drawer"], [])),
    ("stand the bottle up, it tipped over during the test", ("bottle_upright", ["bottle"], [])),
    ("Right, the guests are coming. Close the microwave please", ("close_microwave", ["microwave"], [])),
    ("open the drawer, mind the stuff next to the kettle", ("open_drawer", ["drawer"], ["kettle"])),
    ("open the drawer, there is a lamp beside it that wobbles", ("open_drawer", ["drawer"], ["lamp"])),
    ("sweep the dirt into the dustpan, mind the teeny vase and the many cups",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["small vase", "cup"])),
    ("could you put the laptop charger in the drawer?", ("put_item_in_drawer", ["laptop charger", "drawer"], [])),
    ("open the drawer, keep away from the coffee table book and the mic stand on the left",
     ("open_drawer", ["drawer"], ["coffee table book", "left mic stand"])),
    ("the green bottle stand upright please", ("bottle_upright", ["green bottle"], [])),
    ("close the microwave, my 3 year old keeps opening it", ("close_microwave", ["microwave"], [])),
    ("open the drawer, my son put a cup there", ("open_drawer", ["drawer"], ["cup"])),  # not "put son in drawer"
    ("my flatmate set it up yesterday, please close the microwave", ("close_microwave", ["microwave"], [])),
    # "the others" / "the rest" beside a target are the other objects of its kind, never the target itself
    ("put the pink phone on the base, leave the others be", ("phone_on_base", ["pink phone", "base"],
                                                             ["other phone"])),
    ("stand the red bottle upright, don't touch the rest", ("bottle_upright", ["red bottle"], ["other bottle"])),
    ("close the microwave. back drawer is stuck, leave it be", ("close_microwave", ["microwave"], ["back drawer"])),
    # found by the blind table 23 (hurried and non-native phrasing): present continuous requests, a permission
    # to move an object is no task, a caution after the object, a side after the noun, a name typed as one word
    ("you are closing the microwave now please", ("close_microwave", ["microwave"], [])),
    ("open the drawer, it is allowed to move the box", ("open_drawer", ["drawer"], [])),  # was: box put in drawer
    ("you can move the block into the drawer", ("put_item_in_drawer", ["block", "drawer"], [])),
    ("open the drawer, the lamp no touching", ("open_drawer", ["drawer"], ["lamp"])),
    ("close the microwave, careful for the teapot at the left side", ("close_microwave", ["microwave"],
                                                                       ["left teapot"])),
    ("open the bottle on the middle", ("open_wine_bottle", ["middle bottle"], [])),
    ("block put in drawer, the top one", ("put_item_in_drawer", ["block", "top drawer"], [])),
    ("put the blue bottle in the drawer quick", ("bottle_in_drawer", ["blue bottle", "drawer"], [])),
    ("water the fern with the wateringcan", ("water_plants", ["watering can", "plant"], [])),
    # found by the blind table 22's first run: a permitted object is never the one carried (was a swap), nor
    # refused as out of place; what a person left is named after "left"; a compound before its plural head
    ("the mug can be moved, put the sponge in the drawer", ("put_item_in_drawer", ["sponge", "drawer"], [])),
    ("close the microwave, no worries if you knock the fruit bowl", ("close_microwave", ["microwave"], [])),
    ("open the drawer, my daughter left crayons and marbles everywhere", ("open_drawer", ["drawer"],
                                                                          ["crayon", "marble"])),
    ("open the drawer, there are tape measures and rulers around it", ("open_drawer", ["drawer"],
                                                                       ["tape measure", "ruler"])),
    ("sit the phone on the dock", ("phone_on_base", ["phone", "base"], [])),
    # colours listed after a kind name one object each; permissions said after the object, unless negated
    ("There are three mugs: red, green and blue. Put the green one in the drawer.",
     ("put_item_in_drawer", ["green mug", "drawer"], ["red mug", "blue mug"])),
    ("open the drawer, the jar can be nudged and the lamp you may touch", ("open_drawer", ["drawer"], [])),
    ("open the drawer, none of the cups can be moved", ("open_drawer", ["drawer"], ["cup"])),
    ("close the microwave, the toaster is in front, be careful", ("close_microwave", ["microwave"], ["toaster"])),
    # found by the blind table 24's first run (and one older fault found while fixing it: "mind the hot water
    # bottle" avoided nothing): a list said to stand around the target, a property before a name
    ("the cacti and the seed trays are all around the fern, water the fern", ("water_plants", ["watering can",
                                                                                "plant"], ["cactus", "seed tray"])),
    ("open the drawer, mind the hot water bottle and the sharp knives", ("open_drawer", ["drawer"],
                                                                          ["water bottle", "knife"])),
    ("thanks for the help earlier, now close the microwave", ("close_microwave", ["microwave"], [])),
    # what the user is looking for is in the drawer or elsewhere, not on the table to be avoided
    ("could you open the drawer? I need to find my passport", ("open_drawer", ["drawer"], [])),
    ("open the drawer please, I'm looking for my keys", ("open_drawer", ["drawer"], [])),
    # found by the blind table 25's first run: an adjective ending in -ly ended the name before it began ("a
    # wobbly lamp" was no object at all), a side said before "some water", counts as words, "go ahead and nudge"
    ("close the microwave. there's a wobbly lamp on top of it", ("close_microwave", ["microwave"], ["lamp"])),
    ("give the fern on the left some water", ("water_plants", ["watering can", "left plant"], [])),
    ("open the drawer and avoid the dominoes, all twelve of them", ("open_drawer", ["drawer"], ["domino"])),
    ("open the drawer, go ahead and nudge the sponge", ("open_drawer", ["drawer"], [])),
    ("open the drawer, the teapot was my aunt's and it's fragile", ("open_drawer", ["drawer"], ["teapot"])),
    # found by the blind table 26's first run: the object before "beside it", a swept substance is never what
    # "them" means, "half done", "are all around it"
    ("close the microwave, the test tubes beside it are fragile", ("close_microwave", ["microwave"], ["test tube"])),
    ("sweep the sand into the dustpan, the lamp and the vases are right there, don't knock them",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["lamp", "vase"])),
    ("there's a lego castle half built next to the drawer, open the drawer", ("open_drawer", ["drawer"],
                                                                               ["lego castle"])),
    ("stand the bottle upright, the toy cars are all around it", ("bottle_upright", ["bottle"], ["toy car"])),
]  # fmt: skip


@pytest.mark.parametrize(("instruction", "plan"), DECLARED, ids=[d[0][:40] for d in DECLARED])
def test_every_named_object_is_a_target_or_an_obstacle(decomposer, instruction, plan):
    assert reading(decomposer, instruction) == plan


def test_an_object_the_parser_cannot_place_is_avoided_and_a_warning_says_so(decomposer):
    plan = decomposer.decompose("Put the block in the drawer next to the ceramic teapot")
    assert plan.obstacle_phrases == ["teapot"]
    assert plan.warnings == ["'teapot' is named but is neither acted on nor said to be avoided; it is avoided"]


PERMITTED = [
    "Put the block in the drawer, bumping the mug is fine",
    "Put the block in the drawer; you may touch the mug",
    "Put the block in the drawer, don't worry about the mug",
    "Put the block in the drawer and ignore the mug",
    "Put the block in the drawer, the mug can be moved",
    "Put the block in the drawer, it's fine to bump the mug",
    "Put the block in the drawer; it's okay if you nudge the mug",
    "Put the block in the drawer, you can knock the mug",
    "Put the block in the drawer, never mind the mug",
    # found by the blind table 7: a permission said of "it", shorthand, "if you have to"
    "Put the block in the drawer, the mug is plastic, bump it if you need to",
    "Put the block in the drawer. mug: contact ok.",
    "Put the block in the drawer; contact with the mug is fine",
    "Put the block in the drawer. Contact with the mug is permitted.",
    "Put the block in the drawer; you needn't worry about brushing the mug",
    "Block -> drawer. Touching the mug OK.",
    "If you have to nudge the mug to reach it, that's fine -- put the block in the drawer",
    "Put the block in the drawer, the mug won't break so don't worry about touching it",
    "Put the block in the drawer, no problem if you graze the mug",  # found by the blind table 11
    "Put the block in the drawer, I don't mind if you bump the mug",  # found by the blind table 12
    "Put the block in the drawer. the mug doesn't matter, push it aside if you need to",  # blind table 12
    "Put the block in the drawer. The spoon and the mug can both be touched.",  # found by the blind table 13
    "Put the block in the drawer, I don't care if you knock the mug",  # found by the blind table 14
    "Put the block in the drawer, I'm not bothered if the mug gets moved",
    "Put the block in the drawer, the mug can get bumped, I don't care",  # found by the blind table 15
    "Put the block in the drawer, the mugs don't matter",  # found by the blind table 16
    "Put the block in the drawer, no need to be careful with the mug",
    "Put the block in the drawer, the mug is tough, bump it all you like",
    "Put the block in the drawer, knocking the mug is no big deal",
    "Put the block in the drawer, it's not a big deal if the mug moves",
    "Put the block in the drawer, feel free to move the lamp and the mug",
    "Put the block in the drawer, it's not necessary to avoid the mug",
    "Put the block in the drawer, its fine if you bump the mug",  # found by the blind table 19
]


@pytest.mark.parametrize("instruction", PERMITTED)
def test_an_object_the_user_permits_contact_with_is_not_avoided(decomposer, instruction):
    assert reading(decomposer, instruction) == ("put_item_in_drawer", ["block", "drawer"], [])


def test_an_avoidance_cue_with_permitted_contact_is_dropped_with_a_warning(decomposer):
    plan = decomposer.decompose("Put the block in the drawer, no need to avoid the mug")
    assert plan.obstacles == []
    assert plan.warnings == ["contact with 'mug' is permitted by the instruction; it is not avoided"]


def test_mentions_are_found_whatever_their_role():
    said = "the coffee mug is on the left side of the table, pour the bowl's contents into the pan near the tin can"
    assert [m.phrase for m in object_mentions(tokenize(said), ["bowl", "pan"])] == ["coffee mug", "bowl", "pan",
                                                                                   "tin can"]
    assert [m.phrase for m in object_mentions(tokenize("open the bottle of wine"), ["bottle", "wine"])] == ["bottle"]
    assert object_mentions(tokenize("water the plant"), ["plant"], ["water"])[0].phrase == "plant"


# ---- item 2: refusals with reasons ---------------------------------------------------------------------------


REFUSALS = [
    (NegatedCommandError, "don't open the drawer", "'don't open the drawer' asks the robot not to do something"),
    (NegatedCommandError, "Do not pour the bowl into the pan.", "'do not pour the bowl into the pan' asks the robot"),
    (NegatedCommandError, "never put the block in the drawer", "'never put the block in the drawer' asks the robot"),
    (NegatedCommandError, "water the plant no wait don't", "'don't water the plant' asks the robot"),  # taken back
    (InstructionNotUnderstoodError, "put the green one in the drawer", "'the green one' refers to no object named"),
    (InstructionNotUnderstoodError, "put the dog in the drawer", "'dog' is a person or an animal; put_item_in_drawer"),
    (UnknownVerbError, "I put the block in the drawer", "no task is asked for: 'put' here says what happened"),
    (ContradictionError, "open the wine bottle but do not touch a single bottle", "'bottle' is the object"),
    (ContradictionError, "pour the bowl into the pan, mind the pan", "'pan' is the object bowl_pour acts on, and "
                                                                      "'mind' says to keep away from it"),
    (NegatedCommandError, "please no open the drawer", "'no open the drawer' asks the robot not to do something"),
    (NegatedCommandError, "you not pour the bowl today", "'not pour the bowl today' asks the robot"),
    (ContradictionError, "put the phone on the base, phones no touching", "'phone' is the object phone_on_base"),
    (NegatedCommandError, "do not, whatever happens, open the drawer", "asks the robot not to do something"),
    (InstructionNotUnderstoodError, "slide the block onto the stool", "'onto the stool' is not where put_item_in"),
    (InstructionNotUnderstoodError, "the green tub, pour it into the pan", "'pour it' means the green tub, which"),
    (UnknownVerbError, "recork the bottle", "'recork' is not a verb any skill is asked for with (skills"),  # no decork
    (SeveralTasksError, "ensure the drawer is open and the microwave is shut", "it asks for two tasks"),
    (ContradictionError, "put the blue block in the drawer, careful, mind all the blocks", "'blue block' is the"),
    (ContradictionError, "pour the bowl into the pan, but mind the pan, never touch it", "'never touch it' means pan"),
    # "careful" asks for care, but what follows "not" is what not to do: touching the phone it places (table 28)
    (ContradictionError, "put the phone on the charger, careful not to touch the phone", "'careful not to touch' says"),
    (UnknownVerbError, "i want the vase in the drawer to stay", "it has no verb that asks for a task"),
    # found by the blind table 31: the task asked again on another object, with no verb of its own
    (SeveralTasksError, "put the red block in the drawer and then the blue one", "asks for the task again"),
    (SeveralTasksError, "pour the bowl into the pan, then the green one too", "asks for the task again"),
    (SeveralTasksError, "put the bottle in the drawer and once you're done close the microwave", "two tasks"),
    (SeveralTasksError, "1) open the drawer 2) close the microwave", "two tasks"),
    (SeveralTasksError, "1) stand bottle upright 2) bottle into cupboard", "a placement beside another task"),
    (SeveralTasksError, "if the bottle fell over stand it up, otherwise open it", "'otherwise', another"),
    (UnknownVerbError, "i don't want the phone on the charger", "no skill fits"),
    (NegatedCommandError, "Please don't move the block into the drawer", "'don't move the block into the drawer'"),
    (SeveralTasksError, "Open the drawer and put the block in it",
     "it asks for two tasks ('open': open_drawer, open_wine_bottle; 'put in': bottle_in_drawer, put_item_in_drawer)"),
    (SeveralTasksError, "put the block in the drawer and close the microwave",
     "two tasks ('put in': bottle_in_drawer, put_item_in_drawer; 'close': close_microwave)"),
    (SeveralTasksError, "Put the block in the drawer, then close it", "'close': close_microwave"),
    (SeveralTasksError, "put the block in the drawer and push the drawer shut if you need to", "'push shut'"),
    (SeveralTasksError, "Water the plant, then sweep the crumbs into the dustpan", "'water': water_plants; 'sweep'"),
    # a task in a clause opened by "before" or "after" is a task too
    (SeveralTasksError, "Before watering the plant, sweep the floor", "'water': water_plants; 'sweep'"),
    (SeveralTasksError, "After opening the drawer, put the block in it", "'open': open_drawer, open_wine_bottle;"),
    (SeveralTasksError, "I want the drawer opened and the block put in it", "'open': open_drawer"),
    (ContradictionError, "Put the bottle in the drawer without touching the bottle",
     "'bottle' is the object bottle_in_drawer acts on, and 'without touching' says to keep away from it"),
    (ContradictionError, "Pour the bowl into the pan and avoid the bowl", "'bowl' is the object bowl_pour acts on"),
    (ContradictionError, "Put the block in the drawer and don't touch it",
     "'don't touch it' can only mean what put_item_in_drawer acts on (block, drawer)"),
    (NegatedCommandError, "Don't you dare put the phone on the base", "'don't you dare put the phone on the base'"),
    (NegatedCommandError, "I don't want you to sweep the dirt into the dustpan", "'don't want you to sweep"),
    (NegatedCommandError, "I don't want the bottle put in the drawer", "'don't want the bottle put in the drawer'"),
    (NegatedCommandError, "Sweeping the dirt into the dustpan won't be necessary", "'sweeping the dirt into the"),
    (NegatedCommandError, "It isn't necessary to put the bottle in the drawer", "'isn't necessary to put the bottle"),
    (ContradictionError, "Stand the bottle upright while avoiding every bottle", "'bottle' is the object"),
    (ContradictionError, "Set the green bottle upright but keep away from every single bottle", "'green bottle'"),
    # verbs of abstaining negate the task verb after them
    (NegatedCommandError, "Refrain from opening the microwave door", "'refrain from opening the microwave door'"),
    (NegatedCommandError, "There's no need to water the plant", "'no need to water the plant' asks the robot"),
    (NegatedCommandError, "You needn't pour the bowl into the pan", "'needn't pour the bowl into the pan'"),
    (NegatedCommandError, "Hold off on putting the phone on the base", "'hold off on putting the phone on the base'"),
    (NegatedCommandError, "Don't bother sweeping the crumbs into the dustpan", "'don't bother sweeping the crumbs"),
    (NegatedCommandError, "Skip closing the microwave", "'skip closing the microwave' asks the robot"),
    (NegatedCommandError, "I wish you didn't open the drawer", "'didn't open the drawer' asks the robot"),
    (NegatedCommandError, "You won't need to sweep the crumbs", "'won't need to sweep the crumbs' asks the robot"),
    (NegatedCommandError, "We'd rather not pour the bowl into the pan", "'not pour the bowl into the pan'"),
    # found by the blind table 6: a question without its "?", an outcome the skill does not produce, a target
    # the user keeps the gripper off
    (InstructionNotUnderstoodError, "why did you open the drawer", "it is a question, not a task"),
    (InstructionNotUnderstoodError, "Pull the drawer closed", "'drawer closed' asks for the drawer to end up closed"),
    (InstructionNotUnderstoodError, "Set the block down on the counter", "'on the counter' is not where"),
    # a place right after the carried object that is no slot of the skill: the drawer would be the wrong place
    (InstructionNotUnderstoodError, "Put the block on the plate",
     "'on the plate' is not where put_item_in_drawer puts things (the drawer)"),
    (InstructionNotUnderstoodError, "put the bottle in the cupboard", "'in the cupboard' is not where bottle_in"),
    (ContradictionError, "Pour the bowl into the pan but keep your hand off the bowl", "'keep off' says to keep"),
    (InstructionNotUnderstoodError, "Is the drawer open?", "it is a question, not a task"),
    (InstructionNotUnderstoodError, "Where did you put the phone?", "it is a question, not a task"),
    (UnknownVerbError, "Smash the bowl into the pan", "'smash' is not a verb any skill is asked for with"),
    (UnknownVerbError, "Blorp the snorf into the drawer", "'blorp' is not a verb any skill is asked for with"),
    (UnknownVerbError, "Stack the red block on the blue block", "'stack' is not a verb any skill is asked for with"),
    (InstructionNotUnderstoodError, "Close the drawer", "no skill fits (verbs: close; objects: drawer)"),
    (InstructionNotUnderstoodError, "Pour the bowl into the drawer", "'drawer' has no place in bowl_pour (bowl, pan)"),
    # forgetting a task, "never mind" before a task verb, and a yes/no question without its "?"
    (NegatedCommandError, "Forget about sweeping the crumbs", "'forget about sweeping the crumbs' asks the robot"),
    (NegatedCommandError, "Never mind pouring the bowl", "'never mind pouring the bowl' asks the robot"),
    (InstructionNotUnderstoodError, "Does the microwave need closing", "it is a question, not a task"),
    (NegatedCommandError, "The drawer must not be opened", "'don't open the drawer' asks the robot"),
    (NegatedCommandError, "Why didn't you water the plant", "'didn't you water the plant' asks the robot"),
    # found by the blind table 8: a task asked for and taken back; what happened before is no request
    (ContradictionError, "Open the drawer while keeping zero contact with any drawer", "'drawer' is the object"),
    (ContradictionError, "The bowl is to be poured into the pan; the bowl itself must not be touched",
     "'bowl' is the object bowl_pour acts on"),
    (InstructionNotUnderstoodError, "Lay the upright bottle on its side", "'on its side' asks for an object to end up"),
    # found by the blind table 9: a task called off, "did not", a question without a leading auxiliary
    (NegatedCommandError, "cmd: open drawer; status=aborted", "'aborted' calls the task off"),
    (NegatedCommandError, "The bowl into the pan to pour, this you must not do", "'must not do' calls the task off"),
    (NegatedCommandError, "I'd be glad if you did not close the microwave", "'not close the microwave'"),
    (InstructionNotUnderstoodError, "Bottle upright or lying down?", "it is a question, not a task"),
    (InstructionNotUnderstoodError, "If I wanted the drawer open, what would you do?", "it is a question"),
    (ContradictionError, "task: open bottle; avoid: bottle", "'bottle' is the object open_wine_bottle acts on"),
    (ContradictionError, "The drawer open, but the drawer never touching", "'drawer' is the object open_drawer"),
    (ContradictionError, "Close the microwave without going anywhere near the microwave", "'microwave' is the object"),
    (ContradictionError, "Pour the bowl into the pan without laying a finger on the bowl", "'bowl' is the object"),
    (InstructionNotUnderstoodError, "I left the drawer open by mistake, can you close it?", "no skill fits"),
    (SeveralTasksError, "The drawer is to be opened and the microwave is to be closed", "'close': close_microwave"),
    (SeveralTasksError, "The bowl is to be poured into the pan, after which the drawer is to be opened",
     "'pour': bowl_pour; 'open'"),
    (NegatedCommandError, "Close the microwave. Hmm, actually, don't close it",
     "it asks for close_microwave and also not to 'close'; say which is meant"),
    (NegatedCommandError, "Last week you opened the drawer and it jammed, so don't open it again",
     "'don't open it again' asks the robot not to do something, and nothing else is asked"),
    # found by the blind table 7: contractions typed without the apostrophe, a participle of state ("fully
    # charged") read as a second request, "plus" and "after that" between two tasks
    (NegatedCommandError, "You shouldnt open the drawer", "'shouldnt open the drawer' asks the robot"),
    (NegatedCommandError, "There's no need to put the phone on its base, the battery is fully charged",
     "'no need to put the phone on its base' asks the robot not to do something, and nothing else is asked"),
    (SeveralTasksError, "Open the drawer plus close the microwave", "'close': close_microwave"),
    (SeveralTasksError, "First pour the bowl into the pan and after that sweep the crumbs into the dustpan",
     "'pour': bowl_pour; 'sweep': sweep_to_dustpan"),
    # found by the blind table 32: advice against the task negates it; a causative asks for each task after it
    (NegatedCommandError, "it's best not to put the block in the drawer",
     "'not to put the block in the drawer' asks the robot not to do something, and nothing else is asked"),
    (NegatedCommandError, "it would be wiser not to open the drawer", "'not to open the drawer' asks the robot"),
    (NegatedCommandError, "probably a good idea not to water the plant today", "'not to water the plant"),
    (SeveralTasksError, "get the drawer opened and the block put in it", "'open': open_drawer"),
    (UnknownVerbError, "i have the drawer opened already", "'have' is not a verb any skill is asked for with"),
]  # fmt: skip


SHORTHAND = [  # tables 8 and 9: a placement without a verb, read as "put" with a warning
    ("The bowl into the pan, please", "bowl_pour(bowl, pan)"),
    ("Sponge -> drawer. Avoid: lamp", "put_item_in_drawer(sponge, drawer); avoid lamp"),
    ("Red block to drawer.", "put_item_in_drawer(red block, drawer)"),
]


@pytest.mark.parametrize(("instruction", "summary"), SHORTHAND)
def test_a_placement_without_a_verb_is_read_as_put_and_says_so(decomposer, instruction, summary):
    plan = decomposer.decompose(instruction)
    assert plan.summary() == summary
    assert any(w.startswith("read '") and "as 'put " in w for w in plan.warnings), plan.warnings


@pytest.mark.parametrize(("error", "instruction", "reason"), REFUSALS, ids=[r[1][:40] for r in REFUSALS])
def test_what_cannot_be_accepted_is_refused_naming_it(decomposer, error, instruction, reason):
    with pytest.raises(error, match=re.escape(reason)) as refused:
        decomposer.decompose(instruction)
    assert "\n" not in str(refused.value)  # one line


NOT_REFUSED = [
    ("Put the block close to the drawer", ("put_item_in_drawer", ["block", "drawer"], [])),  # "close to": a place
    ("Could you put the block in the drawer?", ("put_item_in_drawer", ["block", "drawer"], [])),  # a request
    ("Is it possible to open the drawer", ("open_drawer", ["drawer"], [])),  # a request
    ("Don't forget to water the plant", ("water_plants", ["watering can", "plant"], [])),  # two negations
    ("Open the drawer but don't open the bottle", ("open_drawer", ["drawer"], ["bottle"])),  # another object
    # "contact with" is no permission by itself: "avoid / no contact with X" avoids X
    ("Open the drawer, avoid contact with the vase", ("open_drawer", ["drawer"], ["vase"])),
    ("Open the drawer, no contact with the vase", ("open_drawer", ["drawer"], ["vase"])),
    ("Open the drawer; the lamp must be avoided", ("open_drawer", ["drawer"], ["lamp"])),
    # repairs set off by dashes, passive sequences, units, "that mug" after "the white mug", chat "n"
    ("Put the eraser -- no wait, the stapler -- into the drawer", ("put_item_in_drawer", ["stapler", "drawer"], [])),
    ("Put the red -- sorry, the blue -- block in the drawer", ("put_item_in_drawer", ["blue block", "drawer"], [])),
    ("Open the drawer, avoiding the salt shaker 5 cm to the left of it",
     ("open_drawer", ["drawer"], ["salt shaker"])),
    ("Open the drawer. Distance from the vase must be kept at all times", ("open_drawer", ["drawer"], ["vase"])),
    ("The grey mug got cracked yesterday. Open the drawer without touching that mug",
     ("open_drawer", ["drawer"], ["mug"])),
    ("close the microwave n watch out for the kettle", ("close_microwave", ["microwave"], ["kettle"])),
    ("Water the plant with the mug -- no wait, with the watering can", ("water_plants", ["watering can", "plant"],
                                                                         [])),
    ("Open the drawer; avoid the lamp -- actually, the lamp doesn't matter, bumping it is fine",
     ("open_drawer", ["drawer"], [])),
    ("Avoid the kettle, little one, and then close the microwave", ("close_microwave", ["microwave"], ["kettle"])),
    ("Open the wine bottle standing on the left, next to the vase", ("open_wine_bottle", ["left bottle"], ["vase"])),
    ("I need the bottle standing up again", ("bottle_upright", ["bottle"], [])),
    ("My aunt's teapot is beside the drawer; open the drawer", ("open_drawer", ["drawer"], ["teapot"])),
    ("Pour the bowl into the pan, the kettle's handle is hot", ("bowl_pour", ["bowl", "pan"], ["kettle"])),
    ("Put the bottle in the drawer, avoid the kitchen roll holder", ("bottle_in_drawer", ["bottle", "drawer"],
                                                                     ["kitchen roll holder"])),
    ("yo stick the harmonica in the drawer", ("put_item_in_drawer", ["harmonica", "drawer"], [])),
    ("Please ensure that the bowl is poured into the pan", ("bowl_pour", ["bowl", "pan"], [])),
    ("Place 1x block into the drawer, avoid the mugs x2", ("put_item_in_drawer", ["block", "drawer"], ["mug"])),
    ("task: close microwave; avoid: sextant", ("close_microwave", ["microwave"], ["sextant"])),
    ("run 3; cmd: open the drawer; obstacles: none", ("open_drawer", ["drawer"], [])),
    ("Be a dear and open the drawer, mind the lamp, won't you?", ("open_drawer", ["drawer"], ["lamp"])),
    ("Put the block in the drawer and don't run into the lamp", ("put_item_in_drawer", ["block", "drawer"],
                                                                ["lamp"])),
    ("Could you open the drawer, which is on the left?", ("open_drawer", ["left drawer"], [])),  # where it stands
    ("Open the drawer but take care around the vase; it was my aunt's", ("open_drawer", ["drawer"], ["vase"])),
    ("If there are two bottles, open the green bottle and keep clear of the other one",
     ("open_wine_bottle", ["green bottle"], ["other bottle"])),
    ("Open the drawer, the vase do not touch", ("open_drawer", ["drawer"], ["vase"])),  # the object before the cue
    # a target said without an attribute never covers an object said with one ("the phone of grey colour")
    ("The phone, put it on the base, but the phone of grey colour, this one do not touch",
     ("phone_on_base", ["phone", "base"], ["grey phone"])),
    ("So the kitchen stays tidy, open the drawer", ("open_drawer", ["drawer"], [])),
    # found by the blind table 10: an adverb after an obstacle, a permission "allowed to push", "that's no problem"
    ("Close the microwave. Watch the kettle though.", ("close_microwave", ["microwave"], ["kettle"])),
    ("Open the drawer. You're allowed to push the box aside, just avoid the lamp.",
     ("open_drawer", ["drawer"], ["lamp"])),
    ("Open the drawer. If you bump the cushion that's no problem.", ("open_drawer", ["drawer"], [])),
    ("Get the bottle open for me", ("open_wine_bottle", ["bottle"], [])),
    ("The plant, you must water it with the can, avoiding the lamp",  # "the can" is the watering can
     ("water_plants", ["watering can", "plant"], ["lamp"])),
    ("The red block is to be put in the drawer; the blue block is to remain untouched",
     ("put_item_in_drawer", ["red block", "drawer"], ["blue block"])),
    ("Open the drawer, mind the hot kettle", ("open_drawer", ["drawer"], ["kettle"])),
    ("Open the drawer; every glass in the vicinity is to be avoided", ("open_drawer", ["drawer"], ["glass"])),
    ("Close the microwave. Obstacles: a mug at the front, a jar at the rear",
     ("close_microwave", ["microwave"], ["front mug", "rear jar"])),
    ("This morning I spilled rice everywhere; sweep it into the dustpan", ("sweep_to_dustpan", ["broom", "dustpan"],
                                                                          [])),
    ("The drawer was opened by someone, close the microwave", ("close_microwave", ["microwave"], ["drawer"])),
    ("Why don't you close the microwave", ("close_microwave", ["microwave"], [])),  # a suggestion
    ("Come on, let's pour the bowl into the pan together", ("bowl_pour", ["bowl", "pan"], [])),
    # a task asked for in the passive, and a phrase the user took back
    ("The bowl is to be poured into the pan; the kettle must not be touched",
     ("bowl_pour", ["bowl", "pan"], ["kettle"])),
    ("It is requested that the microwave be closed", ("close_microwave", ["microwave"], [])),
    ("The crumbs should be swept into the dustpan", ("sweep_to_dustpan", ["broom", "dustpan"], [])),
    ("Put the sponge, no, the eraser, in the drawer", ("put_item_in_drawer", ["eraser", "drawer"], [])),
    ("Open the bottle, I mean the drawer", ("open_drawer", ["drawer"], [])),
    ("um so put the phone on its base pls, dont hit the vase lol", ("phone_on_base", ["phone", "base"], ["vase"])),
    # one of several picked by an attribute, and a landmark after a superlative of place
    ("Put the rightmost of the three cubes in the drawer", ("put_item_in_drawer", ["rightmost cube", "drawer"], [])),
    ("Pour the smaller of the two bowls into the pan", ("bowl_pour", ["small bowl", "pan"], [])),
    ("Open the bottle closest to the kettle", ("open_wine_bottle", ["bottle"], ["kettle"])),
    ("Put the block in the drawer, wait, the lamp is in the way", ("put_item_in_drawer", ["block", "drawer"],
                                                                  ["lamp"])),
    ("Never mind the lamp, pour the bowl into the pan", ("bowl_pour", ["bowl", "pan"], [])),  # a permission
    ("The drawer is open. Put the block in it.", ("put_item_in_drawer", ["block", "drawer"], [])),
    ("Take the bowl and pour it into the pan", ("bowl_pour", ["bowl", "pan"], [])),  # one task, two verbs
    ("Set the bottle upright", ("bottle_upright", ["bottle"], [])),
    ("Pour the bowl into the pan, don't spill it", ("bowl_pour", ["bowl", "pan"], [])),  # care, not distance
    ("Pour the bowl into the pan and don't touch the mug", ("bowl_pour", ["bowl", "pan"], ["mug"])),
    ("Put the block in the drawer, no need to hurry", ("put_item_in_drawer", ["block", "drawer"], [])),
    # an unknown word is never read as a word that names no object ("duss" as "dust"): it would be dropped
    ("Avoid the duss and open the drawer", ("open_drawer", ["drawer"], ["duss"])),
    # a word of a target's own name is that target, never an obstacle of its own
    ("Put the tv remote in the drawer", ("put_item_in_drawer", ["tv remote", "drawer"], [])),
    # an object skipped is left alone, so avoided, and never the target
    ("Skip the green bowl and pour the red bowl into the pan", ("bowl_pour", ["red bowl", "pan"], ["green bowl"])),
    # an adverb before an obstacle's phrase is not part of its name
    ("Pour the bowl into the pan, and mind the kettle, particularly the toaster",
     ("bowl_pour", ["bowl", "pan"], ["kettle", "toaster"])),
    # "right" before a place is an adverb, so the sentence it is in asks for no task
    ("There's a stapler right beside the drawer. Put the sponge in the drawer.",
     ("put_item_in_drawer", ["sponge", "drawer"], ["stapler"])),
    # what a thing is made of is no part of its name, as "the wooden drawer" is a drawer
    ("Gently put the plastic frog in the drawer past the mug", ("put_item_in_drawer", ["frog", "drawer"], ["mug"])),
    # found by the blind table 28: care said after "not" with a verb of care is still care; a permission for a
    # compound ("the mouse pad") keeps the object its inner noun names elsewhere ("the mice"); "on its feet" is
    # upright, not "put ... back" into a drawer; "the paint can on the right" is a can, and what "might tip" is an
    # obstacle, a slot word too ("the bowl" beside a drawer task)
    ("pour the bowl into the pan, careful not to knock the pan", ("bowl_pour", ["bowl", "pan"], [])),
    ("put the marker in the drawer. bumping the mouse pad is fine but don't touch the mice",
     ("put_item_in_drawer", ["marker", "drawer"], ["mouse"])),
    ("put the marker in the drawer. avoid the mouse pad, bumping the mouse pad is fine",
     ("put_item_in_drawer", ["marker", "drawer"], [])),
    ("get the bottle back on its feet", ("bottle_upright", ["bottle"], [])),
    ("sweep the sawdust into the dustpan, the wobbly green paint can on the right might tip",
     ("sweep_to_dustpan", ["broom", "dustpan"], ["right green paint can"])),
    ("the can on the left might fall, open the drawer", ("open_drawer", ["drawer"], ["left can"])),
    ("put the block in the drawer, the bowl could tip", ("put_item_in_drawer", ["block", "drawer"], ["bowl"])),
    ("the bowl wobbles, put the block in the drawer", ("put_item_in_drawer", ["block", "drawer"], ["bowl"])),
    ("put the bottle upright, it might roll off", ("bottle_upright", ["bottle"], [])),  # care for the target
    # what "could spill" is what may happen, no second task; a wish for a placement asks for it, when the place
    # ends the clause (not "i want the vase in the drawer to stay")
    ("stand up the bottle on the right, the one on the left is full of glitter and could spill",
     ("bottle_upright", ["right bottle"], ["left bottle"])),
    ("i want the phone on the charger pls, dont knock the picture frame",
     ("phone_on_base", ["phone", "base"], ["picture frame"])),
    ("i want the block in the top drawer", ("put_item_in_drawer", ["block", "top drawer"], [])),
    # found by the blind table 29: kinds of plant are watered, not avoided beside a watered "plant"; a room named to
    # say where is no object; "shove ... into" is "put ... into"
    ("water the roses with the green watering can, mind the trowel and the flower pots",
     ("water_plants", ["green watering can", "plant"], ["trowel", "flower pot"])),
    ("water the ivy", ("water_plants", ["watering can", "plant"], [])),
    ("water the fern, avoid the rose", ("water_plants", ["watering can", "plant"], ["rose"])),
    ("in the garage: open the drawer but steer clear of the oil can", ("open_drawer", ["drawer"], ["oil can"])),
    ("could you shove the green bottle into the drawer", ("bottle_in_drawer", ["green bottle", "drawer"], [])),
    ("don't shove the vase, open the drawer", ("open_drawer", ["drawer"], ["vase"])),
    ("please don't disturb the sleeping cat, just shut the microwave", ("close_microwave", ["microwave"], ["cat"])),
    ("avoid the sleeping bag, open the drawer", ("open_drawer", ["drawer"], ["sleeping bag"])),
    # found by the blind table 30: a size before a tool's noun that is also a verb ("the small brush"), a verb's
    # word inside a noun after the task's verb ("the spark plug"), "thanks a lot"
    ("brush the dirt into the dustpan with the small brush", ("sweep_to_dustpan", ["small broom", "dustpan"], [])),
    ("put the spark plug in the drawer, stay clear of the oil can",
     ("put_item_in_drawer", ["spark plug", "drawer"], ["oil can"])),
    ("Could you open the bottom drawer? Thanks a lot!", ("open_drawer", ["bottom drawer"], [])),
    # found by the blind table 31: what a person did is no part of an object's name ("my son spent ..."); a cafe
    # names where; a list of obstacles after "and then" before a comma is no repeated task
    ("my son spent all morning on that lego tower so please don't knock it over. put the block in the drawer",
     ("put_item_in_drawer", ["block", "drawer"], ["lego tower"])),
    ("hello from the cafe! put the phone on the charger, mind the espresso cup",
     ("phone_on_base", ["phone", "base"], ["espresso cup"])),
    ("avoid the mug and then the vase, open the drawer", ("open_drawer", ["drawer"], ["mug", "vase"])),
    # found by the blind table 32: "get / have the X done" asks for it (not "I have the X opened"); "house" and
    # "home" begin a compound ("the house plant"), alone they name where
    ("get the plant watered please, don't splash the sofa", ("water_plants", ["watering can", "plant"], ["sofa"])),
    ("could you have the microwave closed", ("close_microwave", ["microwave"], [])),
    ("water the house plant", ("water_plants", ["watering can", "house plant"], [])),
    ("open the drawer, avoid the house keys", ("open_drawer", ["drawer"], ["house key"])),
    ("I've done a few jobs around the house, close the microwave", ("close_microwave", ["microwave"], [])),
    # found by the blind table 33: "a coil of X" names X; the state after "get / keep the X" is no part of its
    # name; the unsaid watering can said as "the can" is the tool, not an obstacle; shops and events name
    # where and when
    ("open the drawer, there's a coil of hose beside it", ("open_drawer", ["drawer"], ["hose"])),
    ("water the fern but don't get the newspapers wet", ("water_plants", ["watering can", "plant"], ["newspaper"])),
    ("water the plant on the left, the one on the right is drowning so keep the can away from it",
     ("water_plants", ["watering can", "left plant"], ["right plant"])),
    ("we're opening the shop in ten minutes, close the microwave", ("close_microwave", ["microwave"], [])),
    ("open the wine bottle for the party please", ("open_wine_bottle", ["bottle"], [])),
    # found by the blind table 34: a clause that only says how one of two look-alikes is ("leaks") leaves the
    # slot to the other; a task verb that is a compound's head ("an ice pack") is no verb; a pronoun keeps
    # the whole name the noun phrase said; what a person said names no object; "pop the cork" opens
    ("the green bottle drips, put the yellow bottle in the drawer",
     ("bottle_in_drawer", ["yellow bottle", "drawer"], ["green bottle"])),
    ("an ice pack is next to the phone, put the phone on the base",
     ("phone_on_base", ["phone", "base"], ["ice pack"])),
    ("open the drawer, there are coffee tins and some paint brushes nearby, keep off them",
     ("open_drawer", ["drawer"], ["coffee tin", "paint brush"])),
    ("water the plant, the gardener reckons it needs it", ("water_plants", ["watering can", "plant"], [])),
    ("we're getting ready for a christening, close the microwave", ("close_microwave", ["microwave"], [])),
    ("pop the cork on the wine bottle please", ("open_wine_bottle", ["bottle"], [])),
    # found by the blind table 35: a plural the lexicon lacks is still a plural ("bookends"), and "all of them"
    # after a semicolon takes the list before it; people doing something and outdoor places name no object; a
    # can after the words naming its kind; "thats on the right" says where; "lenses" is more than one lens
    ("There are cufflinks and a lamp by the drawer; keep clear of all of them. Open the drawer.",
     ("open_drawer", ["drawer"], ["cufflink", "lamp"])),
    ("close the microwave, the visitors leave at six", ("close_microwave", ["microwave"], [])),
    ("water the plant, we're going to the beach later", ("water_plants", ["watering can", "plant"], [])),
    ("put the soda can in the drawer", ("put_item_in_drawer", ["soda can", "drawer"], [])),
    ("open the bottle thats on the right", ("open_wine_bottle", ["right bottle"], [])),
    ("mind the two lenses, then open the drawer", ("open_drawer", ["drawer"], ["lens"])),
    ("open the bottle, the synth stand is wobbly", ("open_wine_bottle", ["bottle"], ["synth stand"])),
    # a unit word or a side that ends a compound is its head ("the light meter", "a spinning top"), and a gerund
    # before the phrase's last noun names its kind ("a shoe cleaning kit"); "the water meter" was no object at all
    ("open the drawer without bumping the water meter", ("open_drawer", ["drawer"], ["water meter"])),
    ("close the microwave but mind the spinning top", ("close_microwave", ["microwave"], ["spinning top"])),
    ("open the drawer, avoid the shoe cleaning kit", ("open_drawer", ["drawer"], ["shoe cleaning kit"])),
    # found by the blind table 36: what hangs, sits or lies somewhere is said to be there, not carried; "the X can
    # can tip" is a can and its modal; a unit with no number names a kind ("the pint glass"); a measure in digits
    # names nothing; "keep away from it and open ..." is two clauses, not "keep ... open"; company and slopes
    ("A lamp hangs above the drawer. Put the stapler in the drawer.",
     ("put_item_in_drawer", ["stapler", "drawer"], ["lamp"])),
    ("the gas can can tip over, keep away from it and open the drawer", ("open_drawer", ["drawer"], ["gas can"])),
    ("open the drawer, avoid the pint glass", ("open_drawer", ["drawer"], ["pint glass"])),
    ("open the drawer, mind the 2 litre jug", ("open_drawer", ["drawer"], ["jug"])),
    ("water the plant, we're off to the slopes later", ("water_plants", ["watering can", "plant"], [])),
    ("put the phone on the base, I'm going out with my brother", ("phone_on_base", ["phone", "base"], [])),
    # found by the blind table 37: what is poured from a container is its contents; "the beer glass is ..." is a
    # glass; "..., so close the microwave" is the verb; laughter names nothing; what is only said to be there
    # ("theres a snow globe on top of it") is weak evidence for a skill, and what hangs above is said to be there
    ("could you pour the soup from the green bowl into the pan", ("bowl_pour", ["green bowl", "pan"], [])),
    ("open the wine bottle, the beer glass is next to it", ("open_wine_bottle", ["bottle"], ["beer glass"])),
    ("the cat is so close to the microwave, so close the microwave slowly",
     ("close_microwave", ["microwave"], ["cat"])),
    ("lol pls stand the bottle up", ("bottle_upright", ["bottle"], [])),
    ("slide the drawer out please, theres a snow globe on top of it", ("open_drawer", ["drawer"], ["snow globe"])),
    ("The mobile hangs right above the drawer, so open the drawer", ("open_drawer", ["drawer"], ["mobile"])),
    # found by the blind table 38: a surface is the landmark of a property, never its subject ("every plate on the
    # counter is fragile"); "fell over" after a surface is the verb; what "is right by it" is weak evidence
    ("Open the drawer. Every jar on the shelf is fragile.", ("open_drawer", ["drawer"], ["jar"])),
    ("the mug on the workbench fell over, open the drawer", ("open_drawer", ["drawer"], ["mug"])),
    ("slide the drawer open, the heater is right by it", ("open_drawer", ["drawer"], ["heater"])),
]


@pytest.mark.parametrize(("instruction", "plan"), NOT_REFUSED)
def test_constructions_that_only_look_like_refusals_are_planned(decomposer, instruction, plan):
    assert reading(decomposer, instruction) == plan


# ---- the invariant as a property --------------------------------------------------------------------------------

KNOWN_OBJECTS = ["mug", "vase", "lamp", "kettle", "cup", "glass", "plate", "jar", "candle", "toaster", "teapot"]
# role templates: {o} is an object word; each must end up a target or an obstacle of the plan
ROLES = [
    "avoid the {o}",
    "keep clear of the {o}",
    "without touching the {o}",
    "the {o} is in the way",
    "the {o} is fragile",
    "careful, there's a {o} next to the drawer",
    "there's a {o} next to the drawer",
    "the {o} sits on the left",
    "watch out for the {o}",
    "don't knock over the {o}",
    # classes the blind tables 7-9 found
    "avoid: the {o}",
    "the {o} do not touch",
    "no contact with the {o}",
    "the {o} must not be touched",
    "the {o} stays put",
    "my aunt's {o} is next to it",
]
TASKS = [
    ("open the drawer", {"drawer"}),
    ("pour the bowl into the pan", {"bowl", "pan"}),
    ("put the block in the drawer", {"block", "drawer"}),
    ("water the plant", {"plant"}),
    ("close the microwave", {"microwave"}),
]
unknown_words = st.from_regex(r"[bdfgklmnprstvz][aeiou][bdfgklmnprstvz][aeiou]?[bdfgklmnprstvz]", fullmatch=True)


def _object_words(decomposer):
    return {w for s in decomposer.registry for slot in s.slots for entry in slot.synonyms for w in entry.split()}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    task=st.sampled_from(TASKS),
    roles=st.lists(st.sampled_from(ROLES), min_size=1, max_size=3),
    words=st.lists(st.one_of(st.sampled_from(KNOWN_OBJECTS), unknown_words), min_size=4, max_size=4, unique=True),
    item=st.one_of(st.just(None), unknown_words),
    first=st.booleans(),
)
def test_property_every_object_word_in_any_role_is_a_target_or_an_obstacle(decomposer, task, roles, words, item,
                                                                            first):
    """Random object words (known and unknown) in every role around a task: each one the plan keeps is a target
    or an obstacle, never dropped; an object said to be avoided is never a target."""
    task_text, task_objects = task
    # an object word is one the mention finder reads as an object in "the {w}" (not "mess", "side", "way")
    words = [w for w in words if w not in COMMON_WORDS and w not in _object_words(decomposer)
             and object_mentions(tokenize(f"the {w}"))]
    if item is not None and task_text.startswith("put the block"):
        if item in COMMON_WORDS or item in _object_words(decomposer) or item in words:
            return
        task_text = f"put the {item} in the drawer"
        task_objects = {item, "drawer"}
    clauses = [role.format(o=word) for role, word in zip(roles, words, strict=False)]
    instruction = "; ".join([task_text, *clauses] if first else [*clauses, task_text])
    try:
        plan = decomposer.decompose(instruction)
    except InstructionNotUnderstoodError:
        return  # a refusal acts on nothing, which is safe (how often it happens is the tables' business)
    corrected = {m.group(1): m.group(2) for w in plan.warnings if (m := re.match(r"read '(\w+)' as '(\w+)'", w))}
    target_words = {w for t in plan.targets for w in t.name.split()}
    obstacle_words = {w for o in plan.obstacles for w in o.name.split()}
    slot_words = _object_words(decomposer)
    for _, word in zip(roles, words, strict=False):
        said = singular(corrected.get(word, word))
        if word in corrected and said in slot_words:
            continue  # read as a typo of a slot's word ("pabn" as "pan"): a target's name, not an unknown object
        if word in corrected and item is not None and said == singular(corrected.get(item, item)):
            continue  # "bagb" and "babg" both read as "bag": the typos name one object, the one carried
        assert said in target_words | obstacle_words, (instruction, plan.summary())
        assert said not in target_words, (instruction, plan.summary())  # avoided objects are never targets
    assert task_objects & target_words or {corrected.get(w, w) for w in task_objects} & target_words, (
        instruction, plan.summary()
    )


# Words the rules treat specially (copulas, owners, quantities, negations, positions, pronouns, punctuation) beside
# object words: any sequence of them is read or refused with a reason, never a crash (a "belongs to" at the end of
# a sentence once raised a TypeError).
FUNCTION_WORDS = (
    "the a an my is was are there 's not don't want need can can't it them one ones left right on in into to of "
    "and but , . ? belongs every single all none any both some three 3 if you need to fine ok avoid mind keep "
    "away from careful spilled my son made sits between around whichever theres kids' left-hand"
).split()


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(words=st.lists(st.sampled_from([*FUNCTION_WORDS, *KNOWN_OBJECTS, "drawer", "block", "put", "open", "bottle",
                                       "stand", "pour", "bowl", "pan", "set", "roll"]), max_size=14))
@example(words=["drawer", "on", "bowl", "drawer"])  # a plan whose targets fit no slot order: refused by validation
def test_any_sequence_of_words_is_planned_or_refused_with_a_reason(decomposer, words):
    try:
        decomposer.decompose(" ".join(words) or "open")
    except (InstructionNotUnderstoodError, PlanValidationError):
        pass  # a refusal names what it could not accept
