"""The reference tables of the documentation, generated from the code: never edit them by hand.

    python docs/gen_reference.py            # rewrite the generated blocks of docs/cli-options.md and
                                            # docs/guidance-settings.md
    python docs/gen_reference.py --check    # exit 1, naming each page whose blocks differ from the code

A generated block sits between `<!-- generated: NAME -->` and `<!-- end: NAME -->` in its page; the text around
it is written by hand. The blocks:

    eval-options, run-options   `lano3dp eval` / `lano3dp run` options by help panel, read from the typer app
                                (option, value, default, the config path `--set` and `--config` use, the help)
    presets                     every field of the guidance settings tree under each built-in preset, read from
                                `guidance_preset(name)`
    filters                     the built-in chunk filters: what each needs earlier in the list, its options
    tunings                     the packaged policies' guidance.json: the preset and the overrides

tests/test_docs_pages.py runs the check, and reads the preset table back against `guidance_preset` itself.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
BUILTIN_PRESETS = ("none", "a_k", "paper", "recommended")  # the library's own; "tuned" depends on a checkpoint
PANEL_ORDER = ("Options", "Settings", "Perception", "Advanced")
VALUE_NAMES = {"Path": "PATH", "int": "N", "float": "X", "str": "TEXT"}
# options the commands map onto the config by hand (not in EVAL_FIELDS / RUN_FIELDS)
OTHER_PATHS = {"out": "out", "map_": "mapping.PHRASE"}
# where each block goes
PAGES = {"eval-options": "docs/cli-options.md", "run-options": "docs/cli-options.md",
         "presets": "docs/guidance-settings.md", "filters": "docs/guidance-settings.md",
         "tunings": "docs/guidance-settings.md"}


def cell(text: Any) -> str:
    """Text for a Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def table(header: list[str], rows: list[list[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows])


def flow(value: Any) -> str:
    """A settings value as YAML flow text, as `--set` takes it: clean, 0.04, null, true, [repair, hold], {}."""
    import yaml

    return yaml.safe_dump(value, default_flow_style=True, width=10_000).strip().removesuffix("\n...").strip()


# ---- the command line ------------------------------------------------------------------------------------------
def _value(param) -> str:
    if getattr(param, "is_flag", False):
        return ""
    if param.metavar:
        return param.metavar
    annotation = param.type_descriptor.annotation
    name = getattr(annotation, "__name__", None) or str(annotation)
    inner = getattr(annotation, "__args__", None)
    if inner:  # list[str]: a repeatable option
        name = inner[0].__name__
    return VALUE_NAMES.get(name, name.upper())


def _default(param) -> str:
    default = param.default
    if default is None or default is False or (param.multiple and not default):
        return ""
    return "on" if default is True else f"`{default}`"


def options_block(command: str) -> str:
    """`lano3dp <command>`'s options as one table per help panel, in the order --help shows them."""
    import typer

    from lano3dp.cli import app
    from lano3dp.cli.eval_cmd import EVAL_FIELDS
    from lano3dp.cli.run_cmd import RUN_FIELDS

    fields = {**OTHER_PATHS, **{"eval": EVAL_FIELDS, "run": RUN_FIELDS}[command]}
    click_command = typer.main.get_command(app).commands[command]
    panels: dict[str, list[list[str]]] = {}
    for param in click_command.params:
        if param.param_type_name == "argument":
            panels.setdefault("Arguments", []).append([f"`{param.name.upper()}`", "", "", f"`{param.name}`",
                                                       param.help or ""])
            continue
        names = ", ".join(f"`{name}`" for name in [*param.opts, *param.secondary_opts])
        path = fields.get(param.name)
        panels.setdefault(param.rich_help_panel or "Options", []).append(
            [names + (" (repeatable)" if param.multiple else ""), f"`{_value(param)}`" if _value(param) else "",
             _default(param), f"`{path}`" if path else "", param.help or ""])
    order = ["Arguments", *PANEL_ORDER, *sorted(set(panels) - {"Arguments", *PANEL_ORDER})]
    parts = []
    for panel in order:
        if panel in panels:
            parts += [f"**{panel}**", "", table(["option", "value", "default", "setting", "what it does"],
                                                panels[panel]), ""]
    return "\n".join(parts).rstrip()


# ---- the guidance settings ---------------------------------------------------------------------------------------
def leaves(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """{"sampler": {"rho": 0.04}} -> {"sampler.rho": 0.04}; a free-keyed dict (filter options) stays one leaf."""
    flat = {}
    for key, value in tree.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict) and path != "execution.options":
            flat.update(leaves(value, f"{path}."))
        else:
            flat[path] = value
    return flat


def preset_leaves(name: str) -> dict[str, Any]:
    from lano3dp.guidance.settings import guidance_preset

    return leaves(guidance_preset(name).to_dict())


def presets_block() -> str:
    """Every field under each built-in preset; values other than the recommended preset's in bold."""
    columns = {name: preset_leaves(name) for name in BUILTIN_PRESETS}
    recommended = columns["recommended"]
    rows = []
    for path, default in recommended.items():
        rows.append([f"`{path}`", *(f"`{flow(values[path])}`" if values[path] == default
                                    else f"**`{flow(values[path])}`**" for values in columns.values())])
    return table(["setting", *(f"`{name}`" for name in BUILTIN_PRESETS)], rows)


def filters_block() -> str:
    from lano3dp.guidance.execution import build_filters
    from lano3dp.guidance.settings import guidance_preset

    rows = []
    # every built-in filter, in the order they run (filters registered from outside are not the library's)
    for built in build_filters(guidance_preset("recommended").execution):
        cls, name = type(built), built.name
        options = [f"`{f.name}` = `{flow(f.default)}`" for f in dataclasses.fields(cls.Options)]
        rows.append([f"`{name}`", ", ".join(f"`{r}`" for r in cls.requires) or "–", ", ".join(options) or "none",
                     (sys.modules[cls.__module__].__doc__ or "").strip().split("\n")[0].split(": ", 1)[-1]])
    return table(["filter", "needs earlier", "options (default)", "what it does"], rows)


def tunings_block() -> str:
    from lano3dp.guidance.settings import load_guidance_tuning
    from lano3dp.policy.pretrained import packaged_checkpoints

    rows = []
    for task, folder in sorted(packaged_checkpoints().items()):
        tuning = load_guidance_tuning(folder)
        if tuning is None:
            rows.append([f"`{task}`", "–", "no guidance.json: `tuned` is `recommended`"])
        else:
            rows.append([f"`{task}`", f"`{tuning.preset}`",
                         ", ".join(f"`{path}={flow(value)}`" for path, value in tuning.overrides.items())])
    return table(["packaged policy", "guidance.json preset", "overrides"], rows)


BLOCKS = {"eval-options": lambda: options_block("eval"), "run-options": lambda: options_block("run"),
          "presets": presets_block, "filters": filters_block, "tunings": tunings_block}


def begin(name: str) -> str:
    return f"<!-- generated: {name} (python docs/gen_reference.py; do not edit) -->"


def end(name: str) -> str:
    return f"<!-- end: {name} -->"


def block_text(page: str, name: str) -> str:
    """What a page holds between a block's markers now."""
    text = page[page.index(begin(name)) + len(begin(name)):page.index(end(name))]
    return text.strip("\n")


def pages(root: Path = ROOT) -> dict[Path, str]:
    """Relative path -> the page with every generated block rewritten."""
    out: dict[Path, str] = {}
    for name, page in PAGES.items():
        path = Path(page)
        text = out.get(path) or (root / path).read_text()
        if begin(name) not in text or end(name) not in text:
            raise SystemExit(f"{page} has no block {name}: add the lines {begin(name)!r} and {end(name)!r}")
        pattern = re.compile(re.escape(begin(name)) + ".*?" + re.escape(end(name)), re.S)
        generated = f"{begin(name)}\n{BLOCKS[name]()}\n{end(name)}"
        out[path] = pattern.sub(lambda _, generated=generated: generated, text)  # a function: no escapes read
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="Only report pages whose blocks differ from the code.")
    args = parser.parse_args(argv)
    stale = {path: text for path, text in pages().items() if (ROOT / path).read_text() != text}
    for path, text in stale.items():
        if args.check:
            print(f"{path} differs from what the code gives: run python docs/gen_reference.py", file=sys.stderr)
        else:
            (ROOT / path).write_text(text)
            print(f"wrote {path}")
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    raise SystemExit(main())
