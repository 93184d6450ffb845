"""Score the offline parser on a blind instruction table (rows: instruction, expected plan or null, refuse, class).

Usage: python tests/data/score_blind.py tests/data/instructions_blind_3.json [--rows]

Targets are compared after mapping each slot's registered synonyms onto the slot word, on both sides; obstacles
are compared as written. Any exception from the parser counts as a refusal.
"""

from __future__ import annotations

import argparse
import collections
import json
import signal

from lano3dp.language import OfflineDecomposer
from lano3dp.sim.tasks import skill_registry

FIELDS = ("name", "color", "size", "position")
ROW_SECONDS = 20  # a parse that takes longer is reported, not waited for


def _ref(obj) -> tuple:
    get = obj.get if isinstance(obj, dict) else lambda f: getattr(obj, f)
    return tuple(get(f) for f in FIELDS)


def _canonical(plan: dict, specs: dict) -> dict:
    spec = specs.get(plan["skill"])
    targets = []
    for i, target in enumerate(plan["targets"]):
        name, *rest = _ref(target)
        if spec is not None and i < len(spec.slots) and name in spec.slots[i].synonyms:
            name = spec.slots[i].word
        targets.append((name, *rest))
    return {"skill": plan["skill"], "targets": targets, "obstacles": [_ref(o) for o in plan["obstacles"]]}


def _timeout(signum, frame):
    raise TimeoutError(f"parse took over {ROW_SECONDS} s")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("table")
    parser.add_argument("--rows", action="store_true", help="print every row that is not exact")
    args = parser.parse_args()
    rows = json.load(open(args.table, encoding="utf-8"))
    specs = {spec.name: spec for spec in skill_registry()}
    decomposer = OfflineDecomposer()
    signal.signal(signal.SIGALRM, _timeout)

    count = collections.Counter()
    per_class = collections.defaultdict(lambda: [0, 0])
    for row in rows:
        signal.alarm(ROW_SECONDS)
        try:
            got = decomposer.decompose(row["instruction"])
            plan = {"skill": got.skill, "targets": list(got.targets), "obstacles": list(got.obstacles)}
            warned = bool(got.warnings)
            error = None
        except TimeoutError as exc:
            plan, warned, error = None, False, str(exc)
            count["timeouts"] += 1
        except Exception as exc:  # any failure to plan is a refusal
            plan, warned, error = None, False, f"{type(exc).__name__}: {exc}"
        finally:
            signal.alarm(0)
        expected = row["expected"]
        want = _canonical(expected, specs) if expected else None
        have = _canonical(plan, specs) if plan else None
        exact = want == have
        count["rows"] += 1
        count["exact"] += exact
        per_class[row["class"]][0] += exact
        per_class[row["class"]][1] += 1
        if expected is None:
            count["must_refuse"] += 1
            if plan is not None:
                count["planned_must_refuse"] += 1
                count[f"planned_{row['refuse']}"] += 1
        elif plan is None:
            count["refused_plan_expected"] += 1
        else:
            target_names = {t[0] for t in have["targets"]} | {_ref(t)[0] for t in plan["targets"]}
            have_obstacle_names = {o[0] for o in have["obstacles"]}
            dropped = [o for o in want["obstacles"] if o[0] not in have_obstacle_names]
            count["expected_obstacles"] += len(want["obstacles"])
            count["obstacles_dropped"] += len(dropped)
            count["obstacles_dropped_silently"] += 0 if warned else len(dropped)
            count["plans_dropping_obstacles"] += bool(dropped)
            count["obstacles_made_targets"] += sum(o[0] in target_names for o in want["obstacles"])
            want_names = {o[0] for o in want["obstacles"]} | {t[0] for t in want["targets"]}
            count["obstacles_invented"] += sum(o[0] not in want_names for o in have["obstacles"])
            count["wrong_skill"] += have["skill"] != want["skill"]
        if args.rows and not exact:
            print(json.dumps({"class": row["class"], "instruction": row["instruction"], "expected": want,
                              "got": have, "error": error}, ensure_ascii=True))

    print(f"exact plans: {count['exact']}/{count['rows']} ({100 * count['exact'] / count['rows']:.1f}%)")
    print(f"named obstacles dropped: {count['obstacles_dropped']} of {count['expected_obstacles']} expected, "
          f"in {count['plans_dropping_obstacles']} plans ({count['obstacles_dropped_silently']} without a warning)")
    print(f"obstacles made targets: {count['obstacles_made_targets']}")
    print(f"obstacles invented (named nowhere as expected): {count['obstacles_invented']}")
    print(f"negated commands planned: {count['planned_negated']}")
    print(f"must-refuse rows planned: {count['planned_must_refuse']} of {count['must_refuse']} ("
          + ", ".join(f"{k[len('planned_'):]} {v}" for k, v in sorted(count.items())
                      if k.startswith("planned_") and k != "planned_must_refuse") + ")")
    print(f"refusals where a plan was expected: {count['refused_plan_expected']}")
    print(f"wrong skill (plan expected and given): {count['wrong_skill']}")
    print(f"timeouts: {count['timeouts']}")
    print("per class (exact/rows):")
    for name, (ok, total) in sorted(per_class.items()):
        print(f"  {name:22s} {ok:3d}/{total:3d}")


if __name__ == "__main__":
    main()
