"""LLM decomposer: any OpenAI-compatible endpoint (OpenAI, vLLM, Ollama's /v1, llama.cpp server).

The reply is only ever parsed as JSON and validated (pydantic, then the skill registry and the
scene); it is never executed. An invalid reply gets one retry with the validation error added
to the conversation; if that fails too, or the endpoint is unreachable or slow, the offline
rule parser answers instead and a `LLMFallbackWarning` says why.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import Literal

from pydantic import ValidationError

from lano3dp.language.exceptions import LanguageError, PlanValidationError
from lano3dp.language.offline import OfflineDecomposer
from lano3dp.language.plan import TaskPlan, plan_json_schema
from lano3dp.language.registry import SceneObjects, SkillRegistry, default_registry, describe_scene

_FENCE = re.compile(r"^\s*```(?:json)?\s*(.*?)\s*```\s*$", re.DOTALL)


class LLMFallbackWarning(UserWarning):
    """The LLM gave no valid plan; the offline parser's plan is used."""


class LLMPlanError(LanguageError):
    """The LLM gave no valid plan and no fallback was configured."""


def _env(*names: str) -> str | None:
    return next((os.environ[n] for n in names if os.environ.get(n)), None)


@dataclass(frozen=True)
class LLMConfig:
    """Where and how to ask.

    Attributes:
        base_url: endpoint root, e.g. "http://127.0.0.1:8000/v1"; None means api.openai.com.
        model: model name the endpoint serves.
        api_key: bearer token; local servers accept any non-empty string.
        timeout: seconds per request (no automatic HTTP retries: a slow LLM falls back instead).
        response_format: "json_schema" (OpenAI, vLLM, Ollama) or "json_object" (llama.cpp's server,
            which rejects json_schema); the schema is in the prompt either way.
        temperature, max_tokens: decoding settings.
    """

    base_url: str | None = None
    model: str = "gpt-4o-mini"
    api_key: str | None = None
    timeout: float = 30.0
    response_format: Literal["json_schema", "json_object"] = "json_schema"
    temperature: float = 0.0
    max_tokens: int = 512

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
    """

    plan: TaskPlan
    source: Literal["llm", "llm_retry", "offline_fallback"]
    errors: list[str] = field(default_factory=list)
    replies: list[str] = field(default_factory=list)


def system_prompt(registry: SkillRegistry) -> str:
    lines = [
        "You turn a robot user's instruction into a task plan, as one JSON object and nothing else.",
        "Skills (choose exactly one; its targets go in the order given):",
    ]
    for skill in registry:
        lines.append(f"- {skill.name}: {skill.description}. targets: {', '.join(skill.slot_words)}")
    lines += [
        "Rules:",
        "- `targets` has one object per slot of the chosen skill, in slot order; an object the instruction"
        " leaves implicit gets the slot word (e.g. 'water the plant' -> watering can, plant).",
        "- Use the slot word as `name` when the user uses a synonym (skillet -> pan); otherwise the noun said.",
        "- `color` and `size` hold the colour and size words said for that object, else null.",
        "- `obstacles` are the objects the user says to avoid, not touch, keep clear of, or that are in the way.",
        "- Objects mentioned for no reason are neither targets nor obstacles.",
        "JSON schema of the reply: " + json.dumps(plan_json_schema(registry.names), separators=(",", ":")),
    ]
    return "\n".join(lines)


def _parse_reply(content: str | None) -> TaskPlan:
    if not content or not content.strip():
        raise ValueError("the reply was empty")
    fenced = _FENCE.match(content)
    return TaskPlan.model_validate_json(fenced.group(1) if fenced else content.strip())


class LLMDecomposer:
    """Instruction -> TaskPlan through an OpenAI-compatible chat endpoint.

    Args:
        config: endpoint settings (see `LLMConfig.from_env`).
        registry: skills the plan must come from (default: the simulator's tasks).
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

        user = f"Instruction: {instruction}"
        if scene_objects is not None:
            user += f"\nObjects in the scene (use only these): {', '.join(describe_scene(scene_objects))}"
        messages = [{"role": "system", "content": system_prompt(self.registry)}, {"role": "user", "content": user}]
        errors: list[str] = []
        replies: list[str] = []
        for attempt in range(2):
            try:
                content = self._ask(messages)
            except openai.OpenAIError as error:
                errors.append(f"endpoint error: {type(error).__name__}: {error}")
                break
            replies.append(content or "")
            try:
                plan = _parse_reply(content)
                if scene_objects is not None:
                    plan = self._grounder.ground(plan, scene_objects)
                plan = self.registry.validate(plan, scene_objects)
                return PlanOutcome(plan, "llm" if attempt == 0 else "llm_retry", errors, replies)
            except (ValueError, ValidationError, PlanValidationError) as error:
                problem = _describe(error)
                errors.append(problem)
                messages += [
                    {"role": "assistant", "content": content or ""},
                    {
                        "role": "user",
                        "content": f"That plan is invalid: {problem}\nReply with the corrected JSON plan only.",
                    },
                ]
        if self.fallback is None:
            raise LLMPlanError(f"the LLM gave no valid plan for '{instruction}': {'; '.join(errors)}")
        warnings.warn(
            LLMFallbackWarning(f"LLM plan rejected ({'; '.join(errors)}); using the offline parser"), stacklevel=2
        )
        return PlanOutcome(self.fallback.decompose(instruction, scene_objects), "offline_fallback", errors, replies)

    def _ask(self, messages: list[dict]) -> str | None:
        if self.config.response_format == "json_schema":
            response_format = {
                "type": "json_schema",
                "json_schema": {"name": "task_plan", "strict": True, "schema": plan_json_schema(self.registry.names)},
            }
        else:
            response_format = {"type": "json_object"}
        response = self.client.chat.completions.create(
            model=self.config.model,
            messages=messages,
            response_format=response_format,
            temperature=self.config.temperature,
            max_tokens=self.config.max_tokens,
            timeout=self.config.timeout,
        )
        if not response.choices:
            return None
        return response.choices[0].message.content


def _describe(error: Exception) -> str:
    if isinstance(error, ValidationError):
        parts = [f"{'.'.join(str(p) for p in e['loc']) or 'reply'}: {e['msg']}" for e in error.errors()[:5]]
        return "the reply does not match the schema (" + "; ".join(parts) + ")"
    return str(error)
