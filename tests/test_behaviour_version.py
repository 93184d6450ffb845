"""BEHAVIOUR_VERSION is kept honest: short reference episodes, replayed, end as they did when it was last set.

A change that alters episodes (what a policy does, what the simulator does, how an episode is measured) bumps
`lano3dp.provenance.BEHAVIOUR_VERSION`, so that cached results made before it no longer count as current; then the
reference below is written again:

    python -c "import sys; sys.path.insert(0, 'tests'); import test_behaviour_version as t; t.write_reference()"

The episodes cover what a refactor of the runtime could move without meaning to: a clean scene, a target hidden
under another object (its cloud carried over), perception that can fail (the error model's per-frame draws), and
a guided episode beside an obstacle. Float rounding differs between CPU models (torch picks other kernels): 17 of
40 bowl_pour episodes recorded on an AMD EPYC ended otherwise on an Intel Xeon, with the same code. So the
reference holds the processor it was recorded on, and on another one the test says so and skips.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lano3dp import provenance
from lano3dp.evaluation import EvalConfig, GuidanceChoice, PerceptionSettings, evaluate
from lano3dp.evaluation.episodes import EpisodeRunner
from lano3dp.guidance import guidance_preset
from lano3dp.runtime import rollout
from lano3dp.sim import render

REFERENCE = Path(__file__).parent / "data" / "behaviour_reference.json"
SEED = 2_000_000  # seeds no table or benchmark uses
EPISODES = {
    "put_item_in_drawer_clean": dict(task="put_item_in_drawer", episodes=2),
    "bowl_pour_clean": dict(task="bowl_pour", episodes=2),
    "bowl_pour_error_model": dict(task="bowl_pour", episodes=2, perception=PerceptionSettings(segmenter="error-model")),
    "put_item_in_drawer_obstacle_guided": dict(task="put_item_in_drawer", episodes=1, variation="obstacle",
                                               obstacle_scenes_only=True, guidance=GuidanceChoice("tuned")),
}
# What an episode's end is; lengths and clearances to 0.1 mm (float rounding of another CPU stays below it).
COMPARED = ("seed", "success", "steps", "collided", "n_collision_steps", "chunk_executed", "error")


def outcome(record: dict) -> dict:
    made = {key: record[key] for key in COMPARED}
    made["path_length"] = round(record["path_length"], 4)
    made["min_clearance"] = None if record["min_clearance"] is None else round(record["min_clearance"], 4)
    return made


def replay() -> dict[str, list[dict]]:
    return {name: [outcome(r) for r in evaluate(EvalConfig(seed=SEED, **kwargs))["episodes"]]
            for name, kwargs in EPISODES.items()}


def write_reference() -> None:
    """Record the reference episodes at this BEHAVIOUR_VERSION (after bumping it), on this processor."""
    REFERENCE.write_text(json.dumps({"behaviour_version": provenance.BEHAVIOUR_VERSION,
                                     "processor": provenance.machine()["processor"], "episodes": replay()},
                                    indent=1) + "\n")


@pytest.mark.slow
def test_reference_episodes_end_as_they_did_at_this_behaviour_version():
    reference = json.loads(REFERENCE.read_text())
    assert reference["behaviour_version"] == provenance.BEHAVIOUR_VERSION, (
        "BEHAVIOUR_VERSION changed: write the reference again (see this module's docstring)")
    here = provenance.machine()["processor"]
    if reference["processor"] != here:
        pytest.skip(f"the reference episodes were recorded on {reference['processor']!r}; float rounding on {here!r} "
                    "ends some otherwise with the same code (write the reference there to check on it)")
    replayed = replay()
    for name, episodes in reference["episodes"].items():
        assert replayed[name] == episodes, (
            f"{name}: episodes end otherwise than at behaviour version {provenance.BEHAVIOUR_VERSION}; bump "
            "BEHAVIOUR_VERSION if that is meant (cached results no longer describe this code), else find what moved")


@pytest.mark.slow
def test_an_episode_renders_only_the_frames_its_policy_observes_and_ends_as_with_every_frame(monkeypatch):
    renders = []
    original = render.FusedRenderer.render
    monkeypatch.setattr(render.FusedRenderer, "render", lambda *a, **k: renders.append(1) or original(*a, **k))
    config = EvalConfig(task="bowl_pour", episodes=1, seed=SEED)
    episodes = EpisodeRunner(config, guidance_preset("none"))
    try:
        every_frame = rollout(episodes.env, episodes.runner, seed=SEED, on_reset=episodes._on_reset,
                              on_frame=lambda frame, info: None)  # a callback that wants every frame
        rendered_every = len(renders)
        observed = rollout(episodes.env, episodes.runner, seed=SEED, on_reset=episodes._on_reset)
    finally:
        episodes.close()
    assert outcome(observed.to_dict()) == outcome(every_frame.to_dict())
    assert rendered_every == every_frame.steps + 1
    assert len(renders) - rendered_every < rendered_every / 4  # a chunk of 8 actions: about one frame in 8
