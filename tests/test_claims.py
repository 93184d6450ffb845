"""The README's claims paragraph says "holds" only when the 95% intervals separate, and compares methods only on the
tasks and training seeds every one of them was measured on."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def claims():
    spec = importlib.util.spec_from_file_location("claims", ROOT / "docs" / "claims.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cell(final: int, variations: dict[str, int] | None = None, episodes: int = 50) -> dict:
    return {"final": {"successes": final, "episodes": episodes},
            "variations": {name: {"successes": s, "episodes": 20} for name, s in (variations or {}).items()}}


def test_verdicts_follow_the_intervals(claims):
    count = claims.Count
    assert claims.verdict(count(45, 50), [count(20, 50), count(10, 50)]) == "holds"
    assert claims.verdict(count(10, 50), [count(45, 50), count(10, 50)]) == "does not hold"
    assert claims.verdict(count(30, 50), [count(25, 50)]) == "not separated at 95%"
    assert claims.verdict(count(0, 0), [count(25, 50)]) == "not measured yet"
    # fewer touches is better: a guided 2/50 against an unguided 45/50 holds
    assert claims.verdict(count(2, 50), [count(45, 50)], higher_is_better=False) == "holds"
    assert claims.verdict(count(45, 50), [count(2, 50)], higher_is_better=False) == "does not hold"


def test_a_task_without_every_method_is_left_out_of_the_comparison(claims):
    protocol = {"cells": 4, "cells_planned": 63, "tasks": {
        "open_drawer": {"objects": {"seeds": {"0": cell(48)}}, "scene": {"seeds": {"0": cell(10)}},
                        "image": {"seeds": {"0": cell(12)}}},
        "water_plants": {"objects": {"seeds": {"0": cell(0)}}}}}  # no baseline yet: not counted for anyone
    text = claims.success_claim(protocol)
    assert text.count("holds") == 1 and "48/50" in text and "(open_drawer)" in text and "water_plants" not in text


def test_a_seed_without_every_method_is_left_out_of_the_comparison(claims):
    protocol = {"tasks": {"open_drawer": {
        "objects": {"seeds": {"0": cell(48), "1": cell(50)}},  # seed 1 ran for Lan-o3dp only: not counted
        "scene": {"seeds": {"0": cell(10)}}, "image": {"seeds": {"0": cell(12)}}}}}
    text = claims.success_claim(protocol)
    assert "Lan-o3dp 48/50" in text and "98/100" not in text


def test_robustness_compares_lan_o3dp_with_perception_that_can_fail_not_the_ground_truth(claims):
    ours = cell(45, {"similar_sim": 20, "similar_error-model": 4, "camera_sim": 20, "camera_error-model": 5})
    protocol = {"tasks": {"put_item_in_drawer": {
        "objects": {"seeds": {"0": ours}},
        "scene": {"seeds": {"0": cell(40, {"similar_sim": 15, "camera_sim": 16})}},
        "image": {"seeds": {"0": cell(40, {"similar_sim": 14, "camera_sim": 15})}}}}}
    text = claims.robustness_claim(protocol)
    assert "can fail): does not hold;" in text  # 9/40 against 31/40: the oracle's 40/40 is beside it
    assert "Lan-o3dp 9/40" in text and "ground-truth masks: 40/40" in text
