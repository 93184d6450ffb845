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
    response_format: str | None = typer.Option(
        None,
        help="auto (default: json_schema, else JSON mode with the schema for servers such as llama.cpp's "
        "that reject it), json_schema or json_object.",
    ),
    embeddings: bool = typer.Option(
        False, help="Map unknown verbs/nouns with MiniLM sentence embeddings (extra: lano3dp[embeddings])."
    ),
    registry: Path | None = typer.Option(None, help="Skill registry JSON (default: the simulator's tasks)."),
    schema: bool = typer.Option(False, help="Print the plan's JSON schema (with the registry's skills) and exit."),
) -> None:
    """Print the plan {skill, targets (in the skill's slot order), obstacles, warnings} as JSON; warnings
    (an ambiguous reference, an LLM reply that was rejected) also go to stderr."""
    import warnings

    from lano3dp.language import LanguageError, SkillRegistry, plan_json_schema
    from lano3dp.sim.tasks import skill_registry

    skills = SkillRegistry.load(registry) if registry is not None else skill_registry()
    if schema:
        typer.echo(json.dumps(plan_json_schema(skills.names), indent=2))
        return
    if not instruction:
        raise typer.BadParameter("give an instruction (or --schema)", param_hint="INSTRUCTION")
    scene = [o.strip() for o in objects.split(",") if o.strip()] if objects else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = _decompose(instruction, scene, skills, llm, embeddings, base_url, model, timeout, response_format)
        except LanguageError as error:
            _echo_warnings(caught)
            typer.echo(f"error: {error}", err=True)
            for note in getattr(error, "__notes__", ()):
                if not any(str(w.message) == note for w in caught):
                    typer.echo(f"note: {note}", err=True)
            raise typer.Exit(2) from None
    # The LLM fallback's warning is already among the plan's warnings; each is printed once.
    shown = _echo_warnings(caught)
    for text in result.warnings:
        if text not in shown:
            typer.echo(f"warning: {text}", err=True)
    typer.echo(result.model_dump_json(indent=2))


def _echo_warnings(caught) -> set[str]:
    """Print recorded warnings (the LLM fallback's among them), also when planning then failed."""
    shown = set()
    for warning in caught:
        if not warning.category.__module__.startswith("lano3dp"):
            continue  # a library's deprecation notice is not about this plan
        text = str(warning.message)
        if text not in shown:
            typer.echo(f"warning: {text}", err=True)
            shown.add(text)
    return shown


def _decompose(instruction, scene, skills, llm, embeddings, base_url, model, timeout, response_format):
    from lano3dp.language import OfflineDecomposer

    matcher = None
    if embeddings:
        from lano3dp.language.embeddings import default_matcher

        matcher = default_matcher()
    offline = OfflineDecomposer(skills, matcher=matcher)
    if not llm:
        return offline.decompose(instruction, scene)
    from lano3dp.language.llm import LLMConfig, LLMDecomposer

    config = LLMConfig.from_env(base_url=base_url, model=model, timeout=timeout, response_format=response_format)
    decomposer = LLMDecomposer(config, skills, fallback=offline)
    try:
        outcome = decomposer.decompose_with_report(instruction, scene)
    except Exception as error:
        if getattr(error, "__notes__", None):  # the LLM failed, then the rules refused
            typer.echo("plan from: offline_fallback (refused)", err=True)
        raise
    taken = f", response format {outcome.response_format}" if outcome.response_format else ""
    typer.echo(f"plan from: {outcome.source}{taken}", err=True)
    return outcome.plan
