"""Issue 13, item 7: plans from any source are de-duplicated and bounded; a broken reply takes the fallback."""

import pytest
from pydantic import ValidationError

from lano3dp.language import TaskPlan
from lano3dp.language.llm import LLMFallbackWarning
from lano3dp.language.plan import MAX_OBSTACLES, ObjectRef, plan_json_schema
from test_language_llm_safety import INSTRUCTION, RIGHT, LlamaCppStub, llm, ref, reply


@pytest.fixture
def llama():
    server = LlamaCppStub()
    yield server
    server.close()


def test_the_same_obstacle_named_a_thousand_times_is_one_obstacle():
    plan = TaskPlan(skill="bowl_pour", targets=[ObjectRef(name="bowl"), ObjectRef(name="pan")],
                    obstacles=[ObjectRef(name="mug")] * 1000 + [ObjectRef(name="kettle")])
    assert plan.obstacle_phrases == ["mug", "kettle"]


def test_too_many_obstacles_or_a_name_of_megabytes_is_refused():
    many = [ObjectRef(name=f"thing {i}") for i in range(MAX_OBSTACLES + 1)]
    with pytest.raises(ValidationError, match=f"at most {MAX_OBSTACLES}"):
        TaskPlan(skill="bowl_pour", targets=[ObjectRef(name="bowl")], obstacles=many)
    with pytest.raises(ValidationError, match="at most 64 characters"):
        ObjectRef(name="mug" * 2_000_000)


def test_the_schema_sent_to_a_model_carries_no_length_bounds():
    assert "maxLength" not in str(plan_json_schema(["bowl_pour"]))


@pytest.mark.parametrize("body", [b"<html>502 Bad Gateway</html>", b"", b'{"choices": [{"index": 0'])
def test_a_reply_that_is_not_a_completion_takes_the_offline_fallback(llama, body):
    llama.script = [("raw", body)]
    with pytest.warns(LLMFallbackWarning, match="endpoint error"):
        outcome = llm(llama).decompose_with_report(INSTRUCTION)
    assert outcome.source == "offline_fallback"
    assert outcome.plan.summary() == "bowl_pour(red bowl, pan); avoid kettle, mug"


def test_a_reply_naming_one_obstacle_many_times_is_taken_once(llama):
    llama.script = [reply("bowl_pour", [ref("bowl", "red"), ref("pan")], [ref("kettle")] * 50 + [ref("mug")]),
                    RIGHT]
    plan = llm(llama).decompose(INSTRUCTION)
    assert plan.obstacle_phrases == ["kettle", "mug"]
