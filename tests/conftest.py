"""Test-wide environment: offline hub, offscreen EGL rendering, one torch thread.

Two cores shared by a busy machine stall badly with two OpenMP threads, so every test
runs torch single-threaded.

The language tests plan with the built-in skills, which are the simulator's tasks: importing
`lano3dp.sim.tasks` installs them as `lano3dp.language.default_registry()` (language cannot import sim).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

try:
    from hypothesis import settings
except ImportError:  # only the property tests need it
    settings = None

import lano3dp.sim.tasks  # noqa: E402,F401  (installs the default skills; see above)

torch.set_num_threads(1)

# Property tests draw the same examples on every run, so a gate passes or fails for the code, not for the draw;
# `HYPOTHESIS_PROFILE=explore pytest ...` draws new ones (and keeps what fails in .hypothesis/). The lower-bounds
# venv of .ci/run runs no property test and has no hypothesis.
if settings is not None:
    settings.register_profile("gate", derandomize=True)
    settings.register_profile("explore", derandomize=False)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "gate"))
