"""The declared lower bounds are the versions CI installs and tests (.ci/lowest.txt), and the pinned versions the
records were measured on stay inside the declared ranges."""

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def requirement(text: str) -> tuple[str, str, str]:
    """'zarr>=3.1.3' -> ('zarr', '>=', '3.1.3'): the name and its first bound (a marker or comment ignored)."""
    match = re.match(r"\s*([A-Za-z0-9_.\-]+)\s*(==|>=)?\s*([0-9][0-9A-Za-z.]*)?", text)
    return match.group(1).lower().replace("_", "-"), match.group(2) or "", match.group(3) or ""


def pinned(path: Path) -> dict[str, str]:
    lines = [line.split("#")[0].strip() for line in path.read_text().splitlines()]
    return {name: version for name, op, version in map(requirement, filter(None, lines)) if op == "=="}


def declared() -> dict[str, str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return {name: version for name, op, version in map(requirement, project["dependencies"]) if op == ">="}


def release(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", version))


def test_ci_installs_every_core_dependency_at_its_declared_lower_bound():
    bounds, lowest = declared(), pinned(ROOT / ".ci" / "lowest.txt")
    assert set(bounds) == set(lowest), "every core dependency has a lower bound, pinned in .ci/lowest.txt"
    for name, bound in bounds.items():
        assert release(lowest[name]) == release(bound) + (0,) * (len(release(lowest[name])) - len(release(bound))), \
            f"{name}: declared >={bound}, CI tests {lowest[name]}"


def test_the_measured_versions_lie_inside_the_declared_ranges():
    bounds, measured = declared(), pinned(ROOT / "constraints.txt")
    assert release(measured["mujoco"]) == (4, 0, 0)  # the shipped records were measured on it
    for name in set(bounds) & set(measured):
        assert release(measured[name]) >= release(bounds[name]), f"{name} {measured[name]} is below >={bounds[name]}"
