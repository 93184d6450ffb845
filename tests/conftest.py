"""Test-wide environment: offline hub, offscreen EGL rendering, one torch thread.

Two cores shared by a busy machine stall badly with two OpenMP threads, so every test
runs torch single-threaded.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

torch.set_num_threads(1)
