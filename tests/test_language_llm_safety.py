"""Issue 16, item 6: the LLM path as a safety net, against local stub servers on 127.0.0.1.

`LlamaCppStub` behaves like llama.cpp's OpenAI-compatible server: it answers the `json_schema`
response format with HTTP 500 and takes `json_object` (with or without a `schema`). Its replies
come from a script, so a test can make it return plausible but wrong plans.
"""

import json
import re
import select
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.language import InputRejectedError, InstructionNotUnderstoodError, OfflineDecomposer
from lano3dp.language.llm import LLMConfig, LLMDecomposer, LLMFallbackWarning, LLMRefusedError


def ref(name, color=None, size=None, position=None):
    return {"name": name, "color": color, "size": size, "position": position}


def reply(skill, targets, obstacles=(), refusal=None):
    return {"refusal": refusal, "skill": skill, "targets": list(targets), "obstacles": list(obstacles)}


class LlamaCppStub:
    """/v1/chat/completions like llama.cpp's server; `script` items are reply dicts, strings,
    ("slow", seconds) to stall until the client hangs up, ("length", text) for a cut-off reply, or
    ("raw", bytes) for an HTTP 200 whose body is those bytes."""

    def __init__(self):
        self.script: list = []
        self.requests: list[dict] = []
        self.statuses: list[int] = []
        self.hung_up = threading.Event()
        stub = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_POST(self):
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                stub.requests.append(body)
                if body.get("response_format", {}).get("type") == "json_schema":
                    # llama.cpp's answer to a response format it cannot turn into a grammar
                    return self._send(500, {"error": {"code": 500, "message": "Unsupported response_format"}})
                item = stub.script.pop(0) if stub.script else "{}"
                finish = "stop"
                if isinstance(item, tuple) and item[0] == "slow":
                    stub._stall(self.connection, item[1])
                    return
                if isinstance(item, tuple) and item[0] == "raw":  # an HTTP 200 whose body is not a completion
                    return self._send_bytes(200, item[1])
                if isinstance(item, tuple) and item[0] == "drip":  # a body sent one byte per interval
                    return self._drip(item[1], item[2])
                if isinstance(item, tuple) and item[0] == "length":
                    finish, item = "length", item[1]
                content = item if isinstance(item, str) else json.dumps(item)
                choice = {"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": finish}
                completion = {"id": "c", "object": "chat.completion", "created": 0, "model": "m"}
                self._send(200, completion | {"choices": [choice]})

            def _send(self, status, payload):
                self._send_bytes(status, json.dumps(payload).encode())

            def _drip(self, data, interval):
                stub.statuses.append(200)
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                try:
                    for k in range(len(data)):
                        self.wfile.write(data[k : k + 1])
                        self.wfile.flush()
                        time.sleep(interval)
                except (BrokenPipeError, ConnectionResetError):
                    stub.hung_up.set()  # the client closed the connection: stop, as a server would

            def _send_bytes(self, status, data):
                stub.statuses.append(status)
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.server.block_on_close = False
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self.thread.start()

    def _stall(self, connection: socket.socket, seconds: float) -> None:
        """Generate "slowly", checking like llama.cpp whether the client is still there."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            readable, _, _ = select.select([connection], [], [], 0.02)
            if readable and connection.recv(1, socket.MSG_PEEK) == b"":
                self.hung_up.set()
                return

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def llama():
    server = LlamaCppStub()
    yield server
    server.close()


def llm(server, fallback="default", **config):
    settings = {"base_url": server.url, "model": "qwen2.5-0.5b-instruct", "timeout": 5.0} | config
    return LLMDecomposer(LLMConfig(**settings), fallback=fallback)


INSTRUCTION = "Pour the red bowl into the pan; the kettle is in the way, and keep clear of the mug"
RIGHT = reply("bowl_pour", [ref("bowl", "red"), ref("pan")], [ref("kettle"), ref("mug")])


# ---- the response format is negotiated -----------------------------------------------------


def test_a_server_rejecting_json_schema_is_asked_in_json_mode_with_the_schema(llama):
    llama.script = [RIGHT, RIGHT]
    decomposer = llm(llama)
    outcome = decomposer.decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm" and outcome.response_format == "json_object_schema"
    assert outcome.plan.summary() == "bowl_pour(red bowl, pan); avoid kettle, mug"
    first, second = llama.requests
    assert first["response_format"]["type"] == "json_schema" and llama.statuses[0] == 500
    assert second["response_format"]["type"] == "json_object"
    assert second["response_format"]["schema"]["required"] == ["refusal", "skill", "targets", "obstacles"]
    assert '"refusal"' in second["messages"][0]["content"]  # and the schema is in the prompt
    assert decomposer.format_errors == ["json_schema: HTTP 500"]
    # The format is negotiated once: the next instruction goes straight to JSON mode.
    decomposer.decompose(INSTRUCTION)
    assert len(llama.requests) == 3 and llama.requests[2]["response_format"]["type"] == "json_object"


def test_forced_json_object_mode_still_has_the_schema_in_the_prompt(llama):
    llama.script = [RIGHT]
    outcome = llm(llama, response_format="json_object").decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm" and llama.requests[0]["response_format"] == {"type": "json_object"}
    assert "JSON schema of the reply" in llama.requests[0]["messages"][0]["content"]


# ---- replies are bounded and cancelled -----------------------------------------------------


def test_replies_are_bounded_and_a_cut_off_reply_is_sent_back(llama):
    llama.script = [("length", '{"refusal": null, "skill": "bowl_pour", "targets": [{"name": "bo'), RIGHT]
    outcome = llm(llama).decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm_retry" and llama.requests[1]["max_tokens"] == 256
    assert outcome.errors == ["the reply was cut off at max_tokens=256; JSON only"]


def test_a_timed_out_request_is_cancelled_so_the_server_stops_generating(llama):
    llama.script = [("slow", 5.0)]
    start = time.monotonic()
    with pytest.warns(LLMFallbackWarning, match="APITimeoutError"):
        outcome = llm(llama, timeout=0.3).decompose_with_report(INSTRUCTION)
    assert outcome.source == "offline_fallback" and time.monotonic() - start < 2.0
    assert llama.hung_up.wait(1.0), "the server never saw the client close the connection"


# ---- an explicit refusal -------------------------------------------------------------------


def test_the_model_may_refuse_and_the_refusal_is_reported(llama):
    llama.script = [reply(None, [], refusal="no skill makes coffee")]
    with pytest.raises(LLMRefusedError, match="the model refused: no skill makes coffee"):
        llm(llama, fallback=None).decompose("Make me a coffee")
    assert len([r for r in llama.requests if r["response_format"]["type"] == "json_object"]) == 1  # no retry


def test_when_the_fallback_refuses_too_the_llm_warning_is_still_given(llama):
    llama.script = [reply(None, [], refusal="no skill makes coffee")]
    with pytest.warns(LLMFallbackWarning, match="the model refused: no skill makes coffee"):
        with pytest.raises(InstructionNotUnderstoodError, match="no skill fits") as raised:
            llm(llama).decompose("Make me a coffee")
    assert raised.value.__notes__ == [
        "LLM plan rejected (the model refused: no skill makes coffee); using the offline parser"
    ]


def test_the_cli_prints_the_llm_warning_also_when_the_fallback_refuses(llama):
    llama.script = [reply(None, [], refusal="no skill makes coffee")]
    result = CliRunner().invoke(app, ["plan", "Make me a coffee", "--llm", "--base-url", llama.url, "--timeout", "5"])
    assert result.exit_code == 2
    assert "warning: LLM plan rejected (the model refused: no skill makes coffee)" in result.stderr
    assert "plan from: offline_fallback (refused)" in result.stderr
    assert "error: cannot plan 'Make me a coffee': no skill fits" in result.stderr


def test_the_cli_prints_a_plans_warnings():
    result = CliRunner().invoke(app, ["plan", "There's a mug next to the vase. Put the block in the drawer, avoid it"])
    assert result.exit_code == 0, result.output
    assert "warning: 'avoid it' may mean mug or vase; avoiding all of them" in result.stderr
    assert json.loads(result.stdout)["warnings"] == ["'avoid it' may mean mug or vase; avoiding all of them"]


# ---- every model plan is cross-checked against the instruction -----------------------------


WRONG = [
    (
        "drops an obstacle",
        reply("bowl_pour", [ref("bowl", "red"), ref("pan")], [ref("kettle")]),
        "the instruction says to avoid 'mug' but the plan has no such obstacle",
    ),
    (
        "invents an obstacle",
        reply("bowl_pour", [ref("bowl", "red"), ref("pan")], [ref("kettle"), ref("mug"), ref("vase")]),
        "the plan avoids 'vase', which the instruction does not mention",
    ),
    (
        "turns a target into an obstacle",
        reply("bowl_pour", [ref("bowl", "red"), ref("pan")], [ref("kettle"), ref("mug"), ref("pan")]),
        "'pan' is a task object in the instruction, not an obstacle",
    ),
    (
        "turns an obstacle into a target",
        reply("bowl_pour", [ref("mug"), ref("pan")], [ref("kettle")]),
        "'mug' is an obstacle in the instruction, not a task object",
    ),
    (
        "changes a target's colour",
        reply("bowl_pour", [ref("bowl", "blue"), ref("pan")], [ref("kettle"), ref("mug")]),
        "the plan gives 'bowl' the color 'blue', not said in the instruction",
    ),
    (
        "drops a target's colour",
        reply("bowl_pour", [ref("bowl"), ref("pan")], [ref("kettle"), ref("mug")]),
        "the instruction says 'red bowl', the plan 'bowl'",
    ),
]


@pytest.mark.parametrize(("what", "wrong", "problem"), WRONG, ids=[w[0] for w in WRONG])
def test_a_plausible_but_wrong_plan_is_refused_and_the_rules_answer(llama, what, wrong, problem):
    llama.script = [wrong, wrong]
    with pytest.warns(LLMFallbackWarning, match="the plan does not match the instruction") as caught:
        outcome = llm(llama).decompose_with_report(INSTRUCTION)
    assert problem in str(caught[0].message)
    assert outcome.source == "offline_fallback"
    assert outcome.plan.summary() == OfflineDecomposer().decompose(INSTRUCTION).summary()
    assert problem in llama.requests[-1]["messages"][-1]["content"]  # the model was told what was wrong


def test_a_renamed_object_is_refused_but_a_scene_name_or_attribute_is_not(llama):
    llama.script = [reply("put_item_in_drawer", [ref("block"), ref("drawer")])] * 2
    with pytest.warns(LLMFallbackWarning, match="the instruction says 'stapler', the plan 'block'"):
        assert llm(llama).decompose("Put the stapler in the drawer").target_phrases == ["stapler", "drawer"]
    scene = {
        "bowl": {"kind": "bowl", "color": "blue", "size": "medium"},
        "pan": {"kind": "pan"},
        "distractor_mug_2": {"kind": "mug", "color": "white"},
    }
    llama.script = [reply("bowl_pour", [ref("bowl", "blue", "medium"), ref("pan")], [ref("distractor_mug_2")])]
    outcome = llm(llama).decompose_with_report("Pour the bowl into the pan and avoid the mug", scene)
    assert outcome.source == "llm" and outcome.plan.obstacle_phrases == ["distractor mug 2"]


def test_a_wrong_plan_corrected_on_retry_is_taken(llama):
    llama.script = [WRONG[0][1], RIGHT]
    outcome = llm(llama).decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm_retry" and outcome.plan.obstacle_phrases == ["kettle", "mug"]


def test_a_skill_the_rules_read_differently_is_kept_with_a_warning(llama):
    llama.script = [reply("put_item_in_drawer", [ref("bottle"), ref("drawer")])]
    outcome = llm(llama).decompose_with_report("Put the bottle in the drawer")
    assert outcome.source == "llm" and outcome.plan.skill == "put_item_in_drawer"
    assert outcome.plan.warnings == [
        "the rules read 'bottle_in_drawer(bottle, drawer)' here; the model chose 'put_item_in_drawer(bottle, drawer)'"
    ]


def test_model_text_is_data_never_code(llama):
    llama.script = [dict(RIGHT, code="__import__('os').system('touch pwned')"), RIGHT]
    outcome = llm(llama).decompose_with_report(INSTRUCTION)
    assert outcome.source == "llm_retry" and "code: Extra inputs are not permitted" in outcome.errors[0]


# ---- issue 34: the endpoint's answer is bounded, and the plan meets the invariant -----------------------------


def completion_bytes(content: str) -> bytes:
    choice = {"index": 0, "message": {"role": "assistant", "content": content}, "finish_reason": "stop"}
    completion = {"id": "c", "object": "chat.completion", "created": 0, "model": "m", "choices": [choice]}
    return json.dumps(completion).encode()


def test_an_html_page_with_http_200_takes_the_fallback_in_one_line(llama):
    llama.script = [("raw", b"<!DOCTYPE html><html><body>" + b"Welcome to nginx! " * 500 + b"</body></html>")]
    with pytest.warns(LLMFallbackWarning) as caught:
        outcome = llm(llama).decompose_with_report(INSTRUCTION)
    (message,) = [str(w.message) for w in caught]
    assert "HTTP 200 with a body that is not JSON (9041 bytes, starting '<!DOCTYPE html><html><body>Welcome to ng')" \
        in message
    assert "\n" not in message and len(message) < 500
    assert outcome.source == "offline_fallback"
    assert outcome.plan.summary() == "bowl_pour(red bowl, pan); avoid kettle, mug"


def test_a_server_dripping_bytes_cannot_hold_the_request_past_its_total_deadline(llama):
    """Each byte arrives well within the timeout, so a per-read timeout never fires; the total one does."""
    llama.script = [("drip", completion_bytes(json.dumps(RIGHT)), 0.05)]
    start = time.monotonic()
    with pytest.warns(LLMFallbackWarning, match="the reply was still arriving after the 1 s deadline"):
        outcome = llm(llama, timeout=1.0).decompose_with_report(INSTRUCTION)
    assert time.monotonic() - start < 2.5  # the whole reply would take ~14 s
    assert outcome.source == "offline_fallback"
    assert llama.hung_up.wait(2.0), "the connection was not closed"


def test_a_reply_larger_than_a_plan_is_cut_off_and_refused(llama):
    llama.script = [("raw", completion_bytes("x" * 100_000))]
    with pytest.warns(LLMFallbackWarning, match="the reply exceeds 64 KiB; not a plan"):
        assert llm(llama).decompose_with_report(INSTRUCTION).source == "offline_fallback"


UNSAFE = [
    (
        "drops an object named only by a property",
        "Put the bottle in the drawer, the glass is fragile",
        reply("bottle_in_drawer", [ref("bottle"), ref("drawer")]),
        "the instruction says to avoid 'glass' but the plan has no such obstacle",
        "bottle_in_drawer(bottle, drawer); avoid glass",
    ),
    (
        "drops a landmark",
        "Open the drawer under the microwave",
        reply("open_drawer", [ref("drawer")]),
        "the instruction says to avoid 'microwave' but the plan has no such obstacle",
        "open_drawer(drawer); avoid microwave",
    ),
    (
        "invents an obstacle",
        "Open the drawer",
        reply("open_drawer", [ref("drawer")], [ref("vase")]),
        "the plan avoids 'vase', which the instruction does not mention",
        "open_drawer(drawer)",
    ),
    (
        "chooses a skill the verb does not ask for",
        "Put the bowl in the drawer",
        reply("bowl_pour", [ref("bowl"), ref("pan")]),
        "the instruction's verbs ('put', 'put in') ask for bottle_in_drawer, phone_on_base",
        "put_item_in_drawer(bowl, drawer)",
    ),
]


@pytest.mark.parametrize(("what", "instruction", "wrong", "problem", "fallback"), UNSAFE, ids=[u[0] for u in UNSAFE])
def test_a_model_plan_that_breaks_the_invariant_is_refused_never_passed(llama, what, instruction, wrong, problem,
                                                                        fallback):
    llama.script = [wrong, wrong]
    with pytest.warns(LLMFallbackWarning) as caught:
        outcome = llm(llama).decompose_with_report(instruction)
    assert problem in str(caught[0].message)
    assert outcome.source == "offline_fallback" and outcome.plan.summary() == fallback
    retry = llama.requests[-1]["messages"]
    assert [m["role"] for m in retry] == ["system", "user", "user"]  # the problem, not the reply, goes back
    assert problem in retry[-1]["content"] and json.dumps(wrong) not in retry[-1]["content"]


@pytest.mark.parametrize(("instruction", "reason"), [
    ("Don't open the drawer", "'don't open the drawer' asks the robot not to do something"),
    ("Open the drawer and put the block in it", "it asks for two tasks"),
    ("Smash the bowl into the pan", "the instruction has no verb that asks for bowl_pour"),
])
def test_a_model_cannot_plan_what_the_instruction_refuses(llama, instruction, reason):
    planned = {"Don't open the drawer": reply("open_drawer", [ref("drawer")]),
               "Open the drawer and put the block in it": reply("put_item_in_drawer", [ref("block"), ref("drawer")]),
               "Smash the bowl into the pan": reply("bowl_pour", [ref("bowl"), ref("pan")])}[instruction]
    llama.script = [planned, planned]
    with pytest.warns(LLMFallbackWarning, match=re.escape(reason)):
        with pytest.raises(InstructionNotUnderstoodError):
            llm(llama).decompose_with_report(instruction)


def test_an_instruction_refused_as_input_is_never_sent(llama):
    with pytest.raises(InputRejectedError, match="at most 1,000 are accepted"):
        llm(llama).decompose_with_report("open the drawer " * 10_000)
    assert llama.requests == []
