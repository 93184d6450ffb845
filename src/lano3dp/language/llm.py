"""LLM decomposer: any OpenAI-compatible endpoint (OpenAI, vLLM, Ollama's /v1, llama.cpp server).

The instruction is normalised and bounded first (`normalize.normalize_instruction`: a refused text is never
sent). The reply is only ever parsed as JSON and validated (pydantic, then the skill registry, a
cross-check against the instruction and the safety invariant of `mentions`, then the scene); it is never
executed. The model may refuse explicitly (`PlanReply.refusal`). An invalid reply gets one retry that quotes
only the problem (never the reply itself); if that fails too, the model refuses, or the endpoint is
unreachable, slow or answers something that is not a completion (an HTML page with HTTP 200), the offline rule
parser answers instead and a `LLMFallbackWarning` says why in one line (also when the rules then refuse too).

Each request has a total deadline (`LLMConfig.timeout`, for the whole reply, not for each read: a server that
drips one byte a second cannot hold it longer) and a bounded reply size (`MAX_REPLY_BYTES`); the body is read
as a stream and the connection closed at either bound.

The response format is negotiated: a JSON schema where the server takes one; a server that
answers it with an HTTP error (llama.cpp's answers 500) is asked again in JSON mode, with the
schema in the request (llama.cpp turns it into a grammar) and always in the prompt.
"""

from __future__ import annotations

import json
import os
import re
import time
import warnings
from dataclasses import dataclass, field
from typing import Literal

from pydantic import ValidationError

from lano3dp.language.crosscheck import cross_check
from lano3dp.language.exceptions import LanguageError, PlanValidationError, quoted
from lano3dp.language.normalize import normalize_instruction
from lano3dp.language.offline import OfflineDecomposer
from lano3dp.language.plan import PlanReply, TaskPlan, plan_json_schema
from lano3dp.language.registry import SceneObjects, SkillRegistry, default_registry, describe_scene

_FENCE = re.compile(r"^\s*```(?:json)?\s*(.*?)\s*```\s*$", re.DOTALL)
# A plan is under 150 tokens; a completion carrying it, its usage and ids is a few kB. More is not a plan.
MAX_REPLY_BYTES = 64 * 1024
_PROBLEM_CHARS = 300  # what a retry or a warning quotes of a problem


class LLMFallbackWarning(UserWarning):
    """The LLM gave no valid plan; the offline parser's plan is used."""


class LLMPlanError(LanguageError):
    """The LLM gave no valid plan and no fallback was configured."""


class LLMRefusedError(LLMPlanError):
    """The model said no skill can do the instruction, and no fallback was configured."""


class EndpointReplyError(LanguageError, ValueError):
    """The endpoint's answer is no completion: not JSON (an HTML error page with HTTP 200), too large, or late."""


# HTTP statuses with which servers reject a response format they do not support (llama.cpp: 500).
_FORMAT_REJECTED = frozenset({400, 415, 422, 500, 501})
_FORMATS = ("json_schema", "json_object_schema", "json_object")


def _env(*names: str) -> str | None:
    return next((os.environ[n] for n in names if os.environ.get(n)), None)


@dataclass(frozen=True)
class LLMConfig:
    """Where and how to ask.

    Attributes:
        base_url: endpoint root, e.g. "http://127.0.0.1:8000/v1"; None means api.openai.com.
        model: model name the endpoint serves.
        api_key: bearer token; local servers accept any non-empty string.
        timeout: seconds for a whole request, reply included (no automatic HTTP retries: a slow LLM falls
            back instead); a request that runs out of time is cancelled (its connection closed, which stops
            generation on llama.cpp and vLLM).
        response_format: "auto" (default: json_schema, and JSON mode with the schema where the server
            rejects that), or one of "json_schema" (OpenAI, vLLM, Ollama), "json_object" (JSON mode,
            schema in the prompt only) to skip the negotiation.
        temperature, max_tokens: decoding settings; a plan is under 150 tokens, so a small bound
            stops a model that rambles instead of letting it run to the timeout.
    """

    base_url: str | None = None
    model: str = "gpt-4o-mini"
    api_key: str | None = None
    timeout: float = 30.0
    response_format: Literal["auto", "json_schema", "json_object"] = "auto"
    temperature: float = 0.0
    max_tokens: int = 256

    @classmethod
    def from_env(cls, **overrides) -> LLMConfig:
        """Settings from LANO3DP_LLM_{BASE_URL,MODEL,API_KEY,TIMEOUT,RESPONSE_FORMAT}, else
        OPENAI_{BASE_URL,MODEL,API_KEY}; keyword arguments that are not None win."""
        values = {
            "base_url": _env("LANO3DP_LLM_BASE_URL", "OPENAI_BASE_URL"),
            "model": _env("LANO3DP_LLM_MODEL", "OPENAI_MODEL"),
            "api_key": _env("LANO3DP_LLM_API_KEY", "OPENAI_API_KEY"),
            "timeout": _env("LANO3DP_LLM_TIMEOUT"),
            "response_format": _env("LANO3DP_LLM_RESPONSE_FORMAT"),
        }
        values.update({k: v for k, v in overrides.items() if v is not None})
        values = {k: v for k, v in values.items() if v is not None}
        if "timeout" in values:
            values["timeout"] = float(values["timeout"])
        return cls(**values)


@dataclass
class PlanOutcome:
    """A plan and how it was obtained.

    Attributes:
        source: "llm" (first reply valid), "llm_retry" (valid after one correction) or "offline_fallback".
        errors: what was wrong with each rejected reply, or why the endpoint failed.
        replies: the raw LLM replies, for logs.
        response_format: the format the server took ("json_schema", "json_object_schema", "json_object"),
            or None if none was.
    """

    plan: TaskPlan
    source: Literal["llm", "llm_retry", "offline_fallback"]
    errors: list[str] = field(default_factory=list)
    replies: list[str] = field(default_factory=list)
    response_format: str | None = None


def system_prompt(registry: SkillRegistry) -> str:
    lines = [
        "You turn a robot user's instruction into a task plan, as one JSON object and nothing else.",
        "If no skill below can do the instruction, reply with `refusal` set to the reason and `skill` null.",
        "Skills (choose exactly one; its targets go in the order given):",
    ]
    for skill in registry:
        lines.append(f"- {skill.name}: {skill.description}. targets: {', '.join(skill.slot_words)}")
    lines += [
        "Rules:",
        "- `targets` has one object per slot of the chosen skill, in slot order; an object the instruction"
        " leaves implicit gets the slot word (e.g. 'water the plant' -> watering can, plant).",
        "- Use the slot word as `name` when the user uses a synonym (skillet -> pan); otherwise the noun said.",
        "- `color`, `size` and `position` hold the colour, size and position words said for that object"
        " ('red', 'small', 'top', 'left', 'nearest'), else null.",
        "- `obstacles` are every object the user says to avoid, not touch, keep clear of, that is in the way,"
        " that counts as an obstacle, or 'but not'; a pronoun ('avoid it') means the object named before it,"
        " never a target.",
        "- Objects mentioned for no reason are neither targets nor obstacles; never name an object the"
        " instruction does not mention (except a slot word it leaves implicit).",
        "- `refusal` is null when you give a plan.",
        "JSON schema of the reply: " + json.dumps(plan_json_schema(registry.names), separators=(",", ":")),
    ]
    return "\n".join(lines)


class _Refused(Exception):
    """The model declined; not an invalid reply, so it is not sent back for correction."""


def _parse_reply(content: str | None) -> TaskPlan:
    if not content or not content.strip():
        raise ValueError("the reply was empty")
    fenced = _FENCE.match(content)
    reply = PlanReply.model_validate_json(fenced.group(1) if fenced else content.strip())
    if reply.refusal:
        raise _Refused(reply.refusal)
    return reply.to_plan()


class LLMDecomposer:
    """Instruction -> TaskPlan through an OpenAI-compatible chat endpoint.

    Args:
        config: endpoint settings (see `LLMConfig.from_env`).
        registry: skills the plan must come from (default: `default_registry()`, the simulator's tasks).
        fallback: parser used when the LLM fails; None raises LLMPlanError instead.
        client: an `openai.OpenAI`-like client (built from `config` when None).
    """

    def __init__(
        self,
        config: LLMConfig | None = None,
        registry: SkillRegistry | None = None,
        fallback: OfflineDecomposer | None | Literal["default"] = "default",
        client=None,
    ):
        self.config = config or LLMConfig.from_env()
        self.registry = registry or default_registry()
        self.fallback = OfflineDecomposer(self.registry) if fallback == "default" else fallback
        # Maps the LLM's words onto scene object kinds the same way the rule parser does.
        self._grounder = self.fallback or OfflineDecomposer(self.registry)
        self._client = client
        self._owns_client = client is None
        self._format: str | None = None  # the negotiated response format, once a server took one
        self.format_errors: list[str] = []  # formats the server rejected, for logs

    @property
    def client(self):
        if self._client is None:
            from openai import OpenAI

            api_key = self.config.api_key or ("unused" if self.config.base_url else None)
            if api_key is None:
                raise LanguageError(
                    "no API key for the LLM: set LANO3DP_LLM_API_KEY (or OPENAI_API_KEY), "
                    "or LANO3DP_LLM_BASE_URL for a local server"
                )
            self._client = OpenAI(
                base_url=self.config.base_url, api_key=api_key, timeout=self.config.timeout, max_retries=0
            )
        return self._client

    def decompose(self, instruction: str, scene_objects: SceneObjects | None = None) -> TaskPlan:
        return self.decompose_with_report(instruction, scene_objects).plan

    def decompose_with_report(self, instruction: str, scene_objects: SceneObjects | None = None) -> PlanOutcome:
        import openai

        normalized = normalize_instruction(instruction)  # refused input raises here, before any request
        instruction = normalized.text
        user = f"Instruction: {instruction}"
        if scene_objects is not None:
            user += f"\nObjects in the scene (use only these): {', '.join(describe_scene(scene_objects))}"
        messages = [{"role": "system", "content": system_prompt(self.registry)}, {"role": "user", "content": user}]
        errors: list[str] = []
        replies: list[str] = []
        for attempt in range(2):
            try:
                content, cut_off = self._ask(messages)
            except (openai.OpenAIError, EndpointReplyError) as error:
                errors.append(f"endpoint error: {type(error).__name__}: {_one_line(str(error))}")
                break
            replies.append(content or "")
            try:
                if cut_off:
                    raise ValueError(f"the reply was cut off at max_tokens={self.config.max_tokens}; JSON only")
                plan = _parse_reply(content)
                self.registry.validate(plan)  # skill and slot order first: their messages are the clearest
                check = cross_check(plan, instruction, self._grounder, scene_objects)
                if check.errors:
                    raise ValueError("the plan does not match the instruction: " + "; ".join(check.errors))
                if scene_objects is not None:
                    plan = self._grounder.ground(plan, scene_objects)
                plan = self.registry.validate(plan, scene_objects)
                plan = plan.model_copy(update={"warnings": [*normalized.warnings, *plan.warnings, *check.warnings]})
                source = "llm" if attempt == 0 else "llm_retry"
                return PlanOutcome(plan, source, errors, replies, self._format)
            except _Refused as refusal:
                errors.append(f"the model refused: {refusal}")
                break
            except (ValueError, ValidationError, PlanValidationError) as error:
                problem = _one_line(_describe(error))
                errors.append(problem)
                # Only the problem goes back: the invalid reply itself (possibly large, possibly an injection
                # the model was fed) is not quoted to the server again.
                messages = [
                    *messages[:2],
                    {
                        "role": "user",
                        "content": f"Your previous plan was invalid: {problem}\n"
                        "Reply with the corrected JSON plan only.",
                    },
                ]
        if self.fallback is None:
            kind = LLMRefusedError if errors and errors[-1].startswith("the model refused") else LLMPlanError
            raise kind(f"the LLM gave no valid plan for '{quoted(instruction)}': {'; '.join(errors)}")
        message = f"LLM plan rejected ({'; '.join(errors)}); using the offline parser"
        # Warned before the fallback runs, so a caller sees why the LLM was passed over even if the rules refuse.
        warnings.warn(LLMFallbackWarning(message), stacklevel=2)
        try:
            plan = self.fallback.decompose(instruction, scene_objects)
        except LanguageError as error:
            error.add_note(message)
            raise
        plan = plan.model_copy(update={"warnings": [message, *plan.warnings]})
        return PlanOutcome(plan, "offline_fallback", errors, replies, self._format)

    def _response_format(self, name: str) -> dict:
        schema = plan_json_schema(self.registry.names)
        if name == "json_schema":
            return {"type": "json_schema", "json_schema": {"name": "task_plan", "strict": True, "schema": schema}}
        if name == "json_object_schema":
            return {"type": "json_object", "schema": schema}  # llama.cpp's server compiles it into a grammar
        return {"type": "json_object"}

    def _ask(self, messages: list[dict]) -> tuple[str | None, bool]:
        """One request: (the reply's text, whether max_tokens cut it off); negotiates the response
        format on the first call ("auto").

        Raises:
            openai.OpenAIError: the endpoint failed (status, connection, a read that timed out).
            EndpointReplyError: the body is not a completion, exceeds `MAX_REPLY_BYTES`, or missed the deadline.
        """
        import openai

        if self._format is not None:
            candidates = [self._format]
        elif self.config.response_format == "auto":
            candidates = list(_FORMATS)
        else:
            candidates = [self.config.response_format]
        deadline = time.monotonic() + self.config.timeout
        for k, name in enumerate(candidates):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise EndpointReplyError(f"no reply within the {self.config.timeout:g} s deadline")
            try:
                body = self._request(name, messages, deadline)
            except openai.APIStatusError as error:
                if error.status_code in _FORMAT_REJECTED and k + 1 < len(candidates):
                    self.format_errors.append(f"{name}: HTTP {error.status_code}")
                    continue
                raise
            except (openai.APITimeoutError, EndpointReplyError):
                self._cancel()
                raise
            self._format = name
            break
        return _completion_text(body)

    def _request(self, name: str, messages: list[dict], deadline: float) -> bytes:
        """The raw body of one completion request, read as a stream within `deadline` and `MAX_REPLY_BYTES`."""
        remaining = max(deadline - time.monotonic(), 0.001)
        with self.client.chat.completions.with_streaming_response.create(
            model=self.config.model,
            messages=messages,
            response_format=self._response_format(name),
            temperature=self.config.temperature,
            max_tokens=self.config.max_tokens,
            timeout=remaining,  # bounds the connection and each read; the loop below bounds the whole body
        ) as response:
            body = bytearray()
            for chunk in response.iter_bytes():
                body += chunk
                if len(body) > MAX_REPLY_BYTES:
                    raise EndpointReplyError(f"the reply exceeds {MAX_REPLY_BYTES // 1024} KiB; not a plan")
                if time.monotonic() > deadline:
                    raise EndpointReplyError(
                        f"the reply was still arriving after the {self.config.timeout:g} s deadline"
                    )
            return bytes(body)

    def _cancel(self) -> None:
        """Drop the connection of a timed-out request: servers stop generating for a closed connection."""
        client = self._client
        if self._owns_client and client is not None:
            client.close()
            self._client = None


def _completion_text(body: bytes) -> tuple[str | None, bool]:
    """(text, cut off by max_tokens) of a chat completion body; EndpointReplyError for anything else."""
    try:
        completion = json.loads(body)
    except (UnicodeDecodeError, json.JSONDecodeError):
        start = body[:40].decode("utf-8", "replace")
        raise EndpointReplyError(
            f"HTTP 200 with a body that is not JSON ({len(body)} bytes, starting {start!r}); is the base URL an "
            "OpenAI-compatible /v1 endpoint?"
        ) from None
    choices = completion.get("choices") if isinstance(completion, dict) else None
    if not isinstance(choices, list):
        raise EndpointReplyError("HTTP 200 with JSON that is not a chat completion (no 'choices')")
    if not choices:
        return None, False
    choice = choices[0] if isinstance(choices[0], dict) else {}
    message = choice.get("message") if isinstance(choice.get("message"), dict) else {}
    content = message.get("content")
    if content is not None and not isinstance(content, str):
        raise EndpointReplyError("HTTP 200 with a completion whose message content is not text")
    return content, choice.get("finish_reason") == "length"


def _one_line(text: str) -> str:
    text = " ".join(text.split())
    return text if len(text) <= _PROBLEM_CHARS else text[: _PROBLEM_CHARS - 1] + "…"


def _describe(error: Exception) -> str:
    if isinstance(error, ValidationError):
        parts = [f"{'.'.join(str(p) for p in e['loc']) or 'reply'}: {e['msg']}" for e in error.errors()[:5]]
        return "the reply does not match the schema (" + "; ".join(parts) + ")"
    return str(error)
