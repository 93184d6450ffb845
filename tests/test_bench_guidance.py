"""bench_guidance's sweep: every point is the paper preset (or none) with the overrides it names, and runs what
the sweep always measured (the sampler's parameters, the scheduler, the cost's densification and push)."""

from bench_loader import load_bench
from lano3dp.guidance import GuidanceConfig, GuidanceMode
from lano3dp.guidance.settings import guidance_preset

bench = load_bench("bench_guidance")


def test_each_sweep_point_is_a_preset_plus_overrides_that_samples_as_the_sweep_defines_it():
    settings = bench.sweep_settings(bench.SweepConfig())
    assert len(settings) == 53
    for setting in settings:
        resolved = setting.settings
        assert (resolved.sampler.scheduler, resolved.sampler.steps) == (setting.scheduler, setting.steps)
        if setting.mode == "none":
            assert setting.guidance is None and resolved.execution.filters == ()
            continue
        assert setting.guidance == GuidanceConfig(GuidanceMode(setting.mode), setting.rho, setting.last_steps,
                                                  push_weight=setting.push_weight,
                                                  guided_clip_range=setting.clip_range)
        assert resolved.cost.metric_push == (setting.cost != "paper")
        assert resolved.cost.densify == (4 if setting.cost == "metric+dense" else 1)
        assert not resolved.cost.anchored and resolved.execution.filters == ()  # the paper's: waypoints, no filters


def test_the_papers_own_point_is_the_paper_preset_itself():
    paper = bench.Setting("ddpm", "clean", 4.0, 10).settings
    assert paper == guidance_preset("paper")
