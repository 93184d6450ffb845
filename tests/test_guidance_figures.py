"""Diagnostics: the recorder keeps metric A_k / A_0|k, and the CLI writes Fig. 5 and Fig. 6."""

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from lano3dp.cli import app
from lano3dp.guidance import Cylinder, GuidanceConfig, GuidanceMode, denoise
from lano3dp.guidance.analytic import GaussianPathPrior, straight_line
from lano3dp.guidance.diagnostics import DenoiseRecorder, evenly_spaced_timesteps, plot_trajectories_by_scale
from lano3dp.guidance.schedulers import DDIMScheduler


def test_recorder_keeps_chosen_steps_in_metric_units():
    scheduler = DDIMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", prediction_type="epsilon")
    line = straight_line([0.0, -0.5, 0.0], [0.0, 0.5, 0.0], 16)
    prior = GaussianPathPrior(line, 0.02, scheduler.alphas_cumprod)
    recorder = DenoiseRecorder(to_metric=lambda a: 2.0 * a[..., :3], timesteps=[90, 0])
    final = denoise(prior, scheduler, (4, 16, 3), num_inference_steps=10, generator=torch.Generator().manual_seed(0),
                    guidance=GuidanceConfig(GuidanceMode.CLEAN, 0.1, 10), cost_fn=Cylinder((0, 0), 0.1),
                    on_step=recorder)
    assert [s.timestep for s in recorder.steps] == [90, 0]
    assert [s.guided for s in recorder.steps] == [False, True]
    # at k = 91 the clean estimate of this prior is essentially its mean; A_k is still noise
    np.testing.assert_allclose(recorder.steps[0].clean_estimate, 2.0 * line.expand(4, 16, 3).numpy(), atol=0.02)
    assert np.abs(recorder.steps[0].sample - recorder.steps[0].clean_estimate).mean() > 0.3
    # at the last step (t = 0) the DDIM output is the clean estimate, then pushed by guidance
    last = recorder.steps[1]
    assert last.sample.shape == (4, 16, 3)
    assert np.abs(2.0 * final.numpy() - last.clean_estimate).max() < 0.1


def test_evenly_spaced_timesteps_keep_both_ends():
    assert evenly_spaced_timesteps(list(range(99, -1, -1)), 4) == [99, 66, 33, 0]
    assert evenly_spaced_timesteps([90, 0], 5) == [90, 0]


def test_rho_figure_counts_colliding_trajectories(tmp_path):
    obstacle = Cylinder((0.0, 0.0), 0.05, margin=0.0)
    through = np.stack([np.zeros(8), np.linspace(-0.3, 0.3, 8), np.zeros(8)], -1)[None]
    around = through + np.array([0.2, 0.0, 0.0])
    path = plot_trajectories_by_scale({0.0: through, 1.0: around}, obstacle, tmp_path / "fig6.png")
    assert path.stat().st_size > 10_000


@pytest.mark.parametrize("variant", [[], ["--cost", "metric+dense", "--push-weight", "alpha_bar", "--clip-range", "3"]],
                         ids=["paper", "metric"])
def test_cli_writes_both_figures_with_the_analytic_prior(tmp_path, variant):
    result = CliRunner().invoke(app, ["guidance-figures", "--analytic", "--obstacle", "0", "0", "0.1", "--out",
                                      str(tmp_path), "--scheduler", "ddim", "--ks", "100,11,1", "--rhos", "0,0.3",
                                      "--rho", "0.3", "--last-steps", "100", "--samples", "4", *variant])
    assert result.exit_code == 0, result.output
    for name in ("fig5_denoising.png", "fig6_rho.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    bad = CliRunner().invoke(app, ["guidance-figures", "--obstacle", "0", "0", "0.1", "--out", str(tmp_path)])
    assert bad.exit_code != 0 and "--analytic" in bad.output
