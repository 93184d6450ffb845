"""The contract every script under bench/ keeps: the same six arguments, and one writer of its results.

    parser = bench_parser(__file__, __doc__, tasks="bowl_pour", episodes=50, seed=1_000_000, workers=2)
    parser.add_argument("--samplers", ...)               # the script's own options
    args = parse(parser, argv)                           # args.tasks is a list
    write_results("obstacles", args, body, markdown=markdown_report)

The shared arguments mean the same in every script:
    --tasks      comma-separated simulator tasks
    --episodes   episodes (or samples) per measured cell
    --seed       the first seed: cells use seed, seed + 1, ... (never a count)
    --workers    processes run at once (1: everything in this process)
    --out-dir    the folder results go to (default: the repository's results/)
    --tag        a suffix of the results files' names: <out-dir>/<name><tag>.json (and .md, plots)
A script without one of these notions (bench_policy measures no task) still takes the option, so every
--help lists the same six, and refuses a value with one line saying why.

A results JSON is `lano3dp.evaluation.results.results_file`: schema, kind, provenance (command, commit, behaviour
version, versions, machine, config), config, then the script's numbers. Its Markdown page is generated from that
JSON, headed by the file it comes from and how it was made; `<out-dir>/INDEX.md` (`make_index.py`) is rewritten
beside it.

This lives in bench/, not the library: its defaults (the repository's results/, commands written as `python
bench/<script>.py`) belong to the repository's scripts; what a user's own benchmark needs, `results_file` and
`lano3dp.provenance`, is in the library already.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from lano3dp.evaluation.results import results_file
from lano3dp.jsonio import to_jsonable, write_json, write_text_atomic
from lano3dp.provenance import source_commit

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "results"
SHARED = ("tasks", "episodes", "seed", "workers", "out_dir", "tag")


class Unused:
    """A shared argument a script has no use for, and why (its value is refused with this reason)."""

    def __init__(self, reason: str):
        self.reason = reason


def bench_parser(script: str, doc: str | None, *, tasks: str | Unused, episodes: int | None | Unused,
                 seed: int | Unused, workers: int | Unused = 1) -> argparse.ArgumentParser:
    """An argument parser with the shared arguments at the script's defaults (`Unused(reason)` for one it lacks).

    Args:
        script: the script's `__file__`; its name goes into the recorded command.
        doc: the script's docstring: its first line is the description, the rest the epilog.
    """
    name = Path(script).name
    head, _, rest = (doc or "").strip().partition("\n")
    parser = argparse.ArgumentParser(prog=f"python bench/{name}", description=head, epilog=rest.strip() or None,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.set_defaults(_script=name, _unused={})
    shared = parser.add_argument_group("shared by every bench script (bench/_contract.py)")

    def add(flag: str, default, kind, meaning: str) -> None:
        dest = flag.removeprefix("--").replace("-", "_")
        if isinstance(default, Unused):
            parser.get_default("_unused")[dest] = default.reason
            shared.add_argument(flag, type=kind, default=None, help=f"not used here: {default.reason}")
        else:  # None: the script's default depends on its other options, and its description says which
            shown = "see the description" if default is None else default
            shared.add_argument(flag, type=kind, default=default, help=f"{meaning} (default: {shown})")

    add("--tasks", tasks, str, "comma-separated simulator tasks")
    add("--episodes", episodes, int, "episodes per measured cell")
    add("--seed", seed, int, "the first seed: seed, seed + 1, ... (not a count)")
    add("--workers", workers, int, "processes run at once (1: all in this process)")
    shared.add_argument("--out-dir", type=Path, default=RESULTS, help="folder of the results files (default: "
                                                                     "results/)")
    shared.add_argument("--tag", default="", help="suffix of the results files' names: <name><tag>.json")
    return parser


def parse(parser: argparse.ArgumentParser, argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse the command line (`argv` None: this process's): `tasks` becomes a list, a value given to an unused
    shared argument is refused, and `args.command` is the command as a user would type it."""
    given = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(given)
    for dest, reason in args._unused.items():
        if getattr(args, dest) is not None:
            parser.error(f"--{dest.replace('_', '-')} does not apply to {args._script}: {reason}")
    if isinstance(args.tasks, str):
        args.tasks = [task for task in args.tasks.split(",") if task]
    if args.workers is not None and args.workers < 1:
        parser.error(f"--workers must be >= 1, got {args.workers}")
    if args.episodes is not None and args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")
    args.command = shlex.join(["python", f"bench/{args._script}", *given])
    source_commit()  # cached now: the code that runs is the checkout at the start, not a commit made meanwhile
    return args


def arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The parsed arguments as a JSON config (what the results' provenance records), paths inside the repository
    written relative to it."""
    skip = {"command", "_script", "_unused", *args._unused}
    return to_jsonable({name: relative(value) if isinstance(value, Path) else value
                        for name, value in vars(args).items() if name not in skip})


def results_path(name: str, args: argparse.Namespace, suffix: str = ".json") -> Path:
    """<out-dir>/<name><tag><suffix>."""
    return Path(args.out_dir) / f"{name}{args.tag}{suffix}"


def write_results(name: str, args: argparse.Namespace, body: Mapping[str, Any], *,
                  markdown: Callable[[dict[str, Any]], str] | None = None, kind: str | None = None,
                  config: Mapping[str, Any] | None = None) -> Path:
    """Write <out-dir>/<name><tag>.json through `results_file` and, with `markdown` (the written record -> the
    page, title first), its .md headed by where it comes from; then refresh <out-dir>/INDEX.md. Returns the JSON.

    Args:
        kind: the results' kind (default: `name`).
        config: what the provenance records as the config (default: the parsed arguments).
    """
    path = results_path(name, args)
    record = to_jsonable(results_file(kind or name, arguments(args) if config is None else config, body,
                                      command=args.command))
    write_json(path, record)
    if markdown is not None:
        write_text_atomic(path.with_suffix(".md"), with_source(markdown(record), path.name, record))
    write_index(path.parent)
    return path


def write_script_results(name: str, *, command: str, config: Mapping[str, Any], body: Mapping[str, Any],
                         markdown: Callable[[dict[str, Any]], str] | None = None, out_dir: Path = RESULTS) -> Path:
    """`write_results` for a script with a parser of its own (subcommands): its command and config given."""
    return write_results(name, argparse.Namespace(out_dir=out_dir, tag="", command=command), body,
                         markdown=markdown, config=config)


def source_line(json_name: str, record: Mapping[str, Any] | None = None) -> str:
    """The line under a page's title that names the JSON it is generated from (and, given it, how that was made)."""
    line = f"Generated from [`{json_name}`]({json_name})"
    if record is None:
        return line + "; its provenance records how it was made."
    made = record.get("provenance") or {}
    commit = made.get("commit")
    at = f"commit {commit[:10]}{' with local changes' if made.get('dirty') else ''}" if commit else "no git commit"
    when = f", {made['created_utc']}" if made.get("created_utc") else ""
    return f"{line}, made by `{made.get('command')}` ({at}{when})."


def with_source(page: str, json_name: str, record: Mapping[str, Any] | None = None) -> str:
    """`page` with `source_line` after its title (the first line)."""
    title, _, rest = page.partition("\n")
    return f"{title}\n\n{source_line(json_name, record)}\n\n{rest.lstrip(chr(10))}".rstrip("\n") + "\n"


def write_index(folder: Path) -> None:
    from make_index import write_index as write  # bench/ is on sys.path for the scripts and bench_loader

    write(folder)


def relative(path: str | Path) -> str:
    """A path inside the repository written relative to it; one outside, as given (no machine paths in results)."""
    resolved = Path(path).resolve()
    return str(resolved.relative_to(ROOT)) if resolved.is_relative_to(ROOT) else str(path)
