"""`lano3dp plan`: decompose an instruction into a TaskPlan and print it as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    app.command("plan")(plan)


def plan(
    instruction: str | None = typer.Argument(None, help='The instruction, e.g. "pour the red bowl into the pan".'),
    objects: str | None = typer.Option(
        None, help="Comma-separated scene object names (red_bowl,pan,...): objects are checked against them."
    ),
    llm: bool = typer.Option(
        False,
        help="Ask an OpenAI-compatible LLM (LANO3DP_LLM_BASE_URL / _MODEL / _API_KEY or OPENAI_*); "
        "falls back to the rules if it fails.",
    ),
    base_url: str | None = typer.Option(None, help="LLM endpoint, e.g. http://127.0.0.1:8000/v1 (overrides env)."),
    model: str | None = typer.Option(None, help="LLM model name (overrides env)."),
    timeout: float | None = typer.Option(None, help="LLM request timeout, seconds."),
    response_format: str | None = typer.Option(None, help="json_schema (default) or json_object (llama.cpp)."),
    embeddings: bool = typer.Option(
        False, help="Map unknown verbs/nouns with MiniLM sentence embeddings (extra: lano3dp[embeddings])."
    ),
    registry: Path | None = typer.Option(None, help="Skill registry JSON (default: the simulator's tasks)."),
    schema: bool = typer.Option(False, help="Print the plan's JSON schema (with the registry's skills) and exit."),
) -> None:
    """Print the plan {skill, targets (in the skill's slot order), obstacles} as JSON."""
    import warnings

    from lano3dp.language import LanguageError, OfflineDecomposer, SkillRegistry, default_registry, plan_json_schema

    skills = SkillRegistry.load(registry) if registry is not None else default_registry()
    if schema:
        typer.echo(json.dumps(plan_json_schema(skills.names), indent=2))
        return
    if not instruction:
        raise typer.BadParameter("give an instruction (or --schema)", param_hint="INSTRUCTION")
    scene = [o.strip() for o in objects.split(",") if o.strip()] if objects else None
    try:
        matcher = None
        if embeddings:
            from lano3dp.language.embeddings import default_matcher

            matcher = default_matcher()
        offline = OfflineDecomposer(skills, matcher=matcher)
        if llm:
            from lano3dp.language.llm import LLMConfig, LLMDecomposer

            config = LLMConfig.from_env(
                base_url=base_url, model=model, timeout=timeout, response_format=response_format
            )
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                outcome = LLMDecomposer(config, skills, fallback=offline).decompose_with_report(instruction, scene)
            for warning in caught:
                typer.echo(f"warning: {warning.message}", err=True)
            typer.echo(f"plan from: {outcome.source}", err=True)
            result = outcome.plan
        else:
            result = offline.decompose(instruction, scene)
    except LanguageError as error:
        typer.echo(f"error: {error}", err=True)
        raise typer.Exit(2) from None
    typer.echo(result.model_dump_json(indent=2))
