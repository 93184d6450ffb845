"""LLM decomposer through the real openai client against a scripted local HTTP server."""

import json
import threading
import time
import warnings
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from lano3dp.language import ObjectRef, TaskPlan, UnknownObjectError
from lano3dp.language.llm import LLMConfig, LLMDecomposer, LLMFallbackWarning, LLMPlanError

GOOD = {
    "skill": "bowl_pour",
    "targets": [{"name": "bowl", "color": "red", "size": None}, {"name": "pan", "color": None, "size": None}],
    "obstacles": [{"name": "mug", "color": "blue", "size": None}],
}
INSTRUCTION = "Pour the red bowl into the pan while avoiding the blue mug"


class FakeLLM:
    """OpenAI-compatible /v1/chat/completions answering from a script; records every request."""

    def __init__(self):
        self.script: list = []
        self.requests: list[dict] = []
        self.headers: list[dict] = []
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_POST(self):
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                fake.requests.append(body)
                fake.headers.append({k.lower(): v for k, v in self.headers.items()})
                reply = fake.script.pop(0) if fake.script else "no more scripted replies"
                if isinstance(reply, tuple) and reply[0] == "sleep":
                    time.sleep(reply[1])
                    reply = GOOD
                if isinstance(reply, tuple) and reply[0] == "status":
                    self._send(reply[1], {"error": {"message": "server exploded", "type": "server_error"}})
                    return
                content = reply if isinstance(reply, str) else json.dumps(reply)
                self._send(
                    200,
                    {
                        "id": "chatcmpl-1",
                        "object": "chat.completion",
                        "created": 0,
                        "model": body["model"],
                        "choices": [
                            {
                                "index": 0,
                                "message": {"role": "assistant", "content": content},
                                "finish_reason": "stop",
                            }
                        ],
                        "usage": {"prompt_tokens": 1, "completion_tokens": 1, "total_tokens": 2},
                    },
                )

            def _send(self, status, payload):
                data = json.dumps(payload).encode()
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client gave up (timeout test)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.server.block_on_close = False  # do not wait for the handler the timeout test left sleeping
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self.thread.start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def fake_llm():
    server = FakeLLM()
    yield server
    server.close()


def decomposer(server, **overrides):
    config = {"base_url": server.url, "model": "fake-planner", "api_key": "secret", "timeout": 5.0} | overrides
    return LLMDecomposer(LLMConfig(**config))


def expected_plan():
    return TaskPlan(
        skill="bowl_pour",
        targets=[ObjectRef(name="bowl", color="red"), ObjectRef(name="pan")],
        obstacles=[ObjectRef(name="mug", color="blue")],
    )


def test_valid_reply_is_parsed_and_the_request_is_structured(fake_llm):
    fake_llm.script = [GOOD]
    outcome = decomposer(fake_llm).decompose_with_report(INSTRUCTION)
    assert outcome.plan == expected_plan() and outcome.source == "llm" and outcome.errors == []
    (request,) = fake_llm.requests
    assert request["model"] == "fake-planner" and request["temperature"] == 0.0
    assert fake_llm.headers[0]["authorization"] == "Bearer secret"
    response_format = request["response_format"]
    assert response_format["type"] == "json_schema" and response_format["json_schema"]["strict"] is True
    assert "bowl_pour" in response_format["json_schema"]["schema"]["properties"]["skill"]["anyOf"][0]["enum"]
    system, user = request["messages"]
    assert "bowl_pour: grasp the bowl and pour its contents into the pan. targets: bowl, pan" in system["content"]
    assert user["content"] == f"Instruction: {INSTRUCTION}"


def test_malformed_reply_gets_one_retry_with_the_error(fake_llm):
    fake_llm.script = ["Sure! Here is the plan: pour the bowl", "```json\n" + json.dumps(GOOD) + "\n```"]
    outcome = decomposer(fake_llm).decompose_with_report(INSTRUCTION)
    assert outcome.plan == expected_plan() and outcome.source == "llm_retry"
    assert len(fake_llm.requests) == 2
    retry_messages = fake_llm.requests[1]["messages"]
    assert [m["role"] for m in retry_messages] == ["system", "user", "user"]  # the invalid reply is not sent back
    assert retry_messages[2]["content"].startswith(
        "Your previous plan was invalid: the reply does not match the schema"
    )
    assert "Invalid JSON" in retry_messages[2]["content"] and "Sure!" not in retry_messages[2]["content"]


def test_unknown_skill_is_corrected_by_the_retry(fake_llm):
    fake_llm.script = [dict(GOOD, skill="make_tea"), GOOD]
    outcome = decomposer(fake_llm).decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm_retry" and outcome.plan.skill == "bowl_pour"
    feedback = fake_llm.requests[1]["messages"][-1]["content"]
    assert "unknown skill 'make_tea'; the registry has: bottle_in_drawer, bottle_upright, bowl_pour" in feedback


def test_two_bad_replies_fall_back_to_the_offline_parser_with_a_warning(fake_llm):
    swapped = dict(GOOD, targets=list(reversed(GOOD["targets"])))
    fake_llm.script = ["not json", swapped]
    with pytest.warns(LLMFallbackWarning, match="in the order \\(bowl, pan\\)"):
        outcome = decomposer(fake_llm).decompose_with_report(INSTRUCTION)
    assert outcome.source == "offline_fallback" and outcome.plan.model_copy(update={"warnings": []}) == expected_plan()
    assert outcome.plan.warnings[0].startswith("LLM plan rejected (the reply does not match the schema")
    assert len(fake_llm.requests) == 2 and len(outcome.errors) == 2
    assert outcome.replies[0] == "not json"


def test_extra_keys_such_as_code_are_rejected_not_run(fake_llm):
    fake_llm.script = [dict(GOOD, code="__import__('os').system('echo hacked')"), GOOD]
    outcome = decomposer(fake_llm).decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm_retry"
    assert "code: Extra inputs are not permitted" in outcome.errors[0]


def test_objects_missing_from_the_scene_are_sent_back_but_never_dropped(fake_llm):
    fake_llm.script = [GOOD, dict(GOOD, obstacles=[])]
    with pytest.warns(LLMFallbackWarning, match="the plan has no such obstacle"):
        with pytest.raises(UnknownObjectError, match="obstacle 'blue mug' is not in the scene") as raised:
            decomposer(fake_llm).decompose_with_report(INSTRUCTION, scene_objects=["red_bowl", "pan"])
    assert "Objects in the scene (use only these): red_bowl, pan" in fake_llm.requests[0]["messages"][1]["content"]
    assert "obstacle 'blue mug' is not in the scene" in fake_llm.requests[1]["messages"][-1]["content"]
    # The rules refuse too, and the refusal still says why the LLM was passed over.
    assert "LLM plan rejected" in raised.value.__notes__[0]


def test_slow_endpoint_times_out_and_falls_back(fake_llm):
    fake_llm.script = [("sleep", 3.0)]
    start = time.monotonic()
    with pytest.warns(LLMFallbackWarning, match="APITimeoutError"):
        outcome = decomposer(fake_llm, timeout=0.3).decompose_with_report(INSTRUCTION)
    assert time.monotonic() - start < 2.0
    assert outcome.source == "offline_fallback" and len(fake_llm.requests) == 1


def test_server_error_falls_back_and_no_fallback_raises(fake_llm):
    fake_llm.script = [("status", 500)] * 3  # every response format the negotiation tries
    with pytest.warns(LLMFallbackWarning, match="InternalServerError"):
        plan = decomposer(fake_llm).decompose(INSTRUCTION)
    assert plan.model_copy(update={"warnings": []}) == expected_plan() and len(fake_llm.requests) == 3
    fake_llm.script = ["nope", "still nope"]
    strict = LLMDecomposer(LLMConfig(base_url=fake_llm.url, model="m", timeout=5), fallback=None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(LLMPlanError, match="no valid plan for 'Pour the red bowl"):
            strict.decompose(INSTRUCTION)


def test_json_object_mode_for_llama_cpp_servers(fake_llm):
    fake_llm.script = [GOOD]
    decomposer(fake_llm, response_format="json_object").decompose(INSTRUCTION)
    assert fake_llm.requests[0]["response_format"] == {"type": "json_object"}


def test_config_from_environment(monkeypatch):
    monkeypatch.setenv("OPENAI_BASE_URL", "http://openai.example/v1")
    monkeypatch.setenv("OPENAI_MODEL", "gpt-x")
    monkeypatch.setenv("LANO3DP_LLM_MODEL", "local-model")
    monkeypatch.setenv("LANO3DP_LLM_TIMEOUT", "7.5")
    monkeypatch.delenv("LANO3DP_LLM_BASE_URL", raising=False)
    monkeypatch.delenv("LANO3DP_LLM_API_KEY", raising=False)
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    config = LLMConfig.from_env()
    assert config == LLMConfig(base_url="http://openai.example/v1", model="local-model", timeout=7.5)
    assert LLMConfig.from_env(model="override", base_url=None).model == "override"
    monkeypatch.delenv("OPENAI_BASE_URL")
    with pytest.raises(Exception, match="LANO3DP_LLM_API_KEY"):
        _ = LLMDecomposer(LLMConfig.from_env()).client


def test_llm_synonyms_are_grounded_in_the_scene(fake_llm):
    skillet = dict(GOOD, targets=[GOOD["targets"][0], {"name": "skillet", "color": None, "size": None}], obstacles=[])
    fake_llm.script = [skillet]
    outcome = decomposer(fake_llm).decompose_with_report(
        "Pour the red bowl into the skillet", scene_objects=["red_bowl", "frying_pan"]
    )
    assert outcome.source == "llm" and outcome.plan.target_phrases == ["red bowl", "pan"]
