"""Layering as a test: a lower layer never imports an upper one, counting function-local imports too.

Layers, lowest first (README "Design", docs/architecture.md): errors, registry, video, jsonio, geometry,
vocabulary < data, perception, language, guidance, policy, mujoco_frame, wrappers < sim < runtime, train, evaluate,
collect, env_factory, pipeline, executor, augment, locking, report, recording < cli. Modules of one layer may import
one another (policy uses guidance's sampler).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "lano3dp"
LAYERS = (
    ("errors", "registry", "video", "jsonio", "config_tree", "provenance", "geometry", "vocabulary"),
    ("data", "perception", "language", "guidance", "policy", "mujoco_frame", "wrappers"),
    ("sim",),
    ("runtime", "train", "evaluation", "collect", "env_factory", "pipeline", "executor", "augment", "locking",
     "report", "recording", "migrate"),
    ("cli",),
)
RANK = {part: rank for rank, parts in enumerate(LAYERS) for part in parts}

# Imports that break the rule today, each (importer, imported layer) with why it is still there.
# Remove an entry when the import goes; the test fails on entries that no longer match anything.
KNOWN_EXCEPTIONS: dict[tuple[str, str], str] = {}


def first_party_imports(path: Path) -> list[tuple[str, int]]:
    """(imported lano3dp module, line) for every import in the file: module level, function-local and
    TYPE_CHECKING blocks alike."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names if alias.name.startswith("lano3dp.")]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "lano3dp":  # `from lano3dp import policy` names a subpackage
                found += [(f"lano3dp.{alias.name}", node.lineno) for alias in node.names]
            elif node.module.startswith("lano3dp."):
                found.append((node.module, node.lineno))
    return found


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def layer_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None  # "lano3dp" itself: the public API, above every layer


def violations() -> dict[tuple[str, str], list[str]]:
    """{(importer, imported layer): ["importer.py:line imports module", ...]} for every upward import."""
    found: dict[tuple[str, str], list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        importer = module_name(path)
        own = layer_of(importer)
        if own is None:  # lano3dp/__init__.py: the public API re-exports every layer (lazily)
            continue
        for imported, line in first_party_imports(path):
            layer = layer_of(imported)
            if layer is None or RANK[layer] > RANK[own]:
                found.setdefault((importer, layer or "lano3dp"), []).append(f"{path.name}:{line} imports {imported}")
    return found


def test_every_package_and_top_level_module_has_a_layer():
    names = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
             if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    assert names - set(RANK) == set(), "give the new module a layer in LAYERS (and in docs/architecture.md)"


def test_lower_layers_never_import_upper_ones():
    found = violations()
    unexpected = {key: where for key, where in found.items() if key not in KNOWN_EXCEPTIONS}
    assert unexpected == {}, "an upward import; move the code down or the import up (see LAYERS)"


def test_the_known_exceptions_still_exist():
    found = violations()
    stale = [key for key in KNOWN_EXCEPTIONS if key not in found]
    assert stale == [], "these imports are gone: delete their KNOWN_EXCEPTIONS entries"


def test_the_checker_sees_function_local_imports(tmp_path):
    source = tmp_path / "probe.py"
    source.write_text("def f():\n    from lano3dp.cli import app\n    import lano3dp.sim.env\n")
    assert first_party_imports(source) == [("lano3dp.cli", 2), ("lano3dp.sim.env", 3)]
