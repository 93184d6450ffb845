"""Rotation conversions. Quaternions are (w, x, y, z), MuJoCo's order.

The 6D representation is the first two columns of the rotation matrix, concatenated
(Zhou et al., CVPR 2019): continuous, so regression targets have no wrap-around.
Functions accept numpy arrays or torch tensors with arbitrary leading batch dimensions.
"""

from __future__ import annotations

import sys

import numpy as np


def _lib(x):
    # torch only when it is already loaded: then x may be a tensor; otherwise it cannot be one, and importing
    # torch here would load it into the simulator, which must stay torch-free
    torch = sys.modules.get("torch")
    return torch if torch is not None and isinstance(x, torch.Tensor) else np


def quat_to_matrix(quat):
    """(..., 4) wxyz -> (..., 3, 3). The quaternion need not be unit length."""
    xp = _lib(quat)
    norm = (quat**2).sum(-1, keepdims=True) ** 0.5
    w, x, y, z = [(quat / norm)[..., i] for i in range(4)]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    return xp.stack([xp.stack(r, -1) for r in rows], -2)


def matrix_to_quat(matrix) -> np.ndarray:
    """(..., 3, 3) -> (..., 4) wxyz with w >= 0 (numpy only; Shepperd's method)."""
    m = np.asarray(matrix, dtype=np.float64)
    batch = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    quats = np.empty((len(m), 4))
    for i, r in enumerate(m):
        trace = np.trace(r)
        if trace > 0:
            s = 2.0 * np.sqrt(trace + 1.0)
            q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
        else:
            k = int(np.argmax(np.diag(r)))
            i1, i2 = (k + 1) % 3, (k + 2) % 3
            s = 2.0 * np.sqrt(1.0 + r[k, k] - r[i1, i1] - r[i2, i2])
            q = np.zeros(4)
            q[0] = (r[i2, i1] - r[i1, i2]) / s
            q[1 + k] = 0.25 * s
            q[1 + i1] = (r[i1, k] + r[k, i1]) / s
            q[1 + i2] = (r[i2, k] + r[k, i2]) / s
        q = np.asarray(q)
        quats[i] = q if q[0] >= 0 else -q
    return quats.reshape(*batch, 4)


def matrix_to_rot6d(matrix):
    """(..., 3, 3) -> (..., 6): first column then second column."""
    xp = _lib(matrix)
    return xp.concatenate([matrix[..., :, 0], matrix[..., :, 1]], -1)


def rot6d_to_matrix(rot6d):
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt, so any non-degenerate 6-vector gives a rotation."""
    xp = _lib(rot6d)
    a1, a2 = rot6d[..., :3], rot6d[..., 3:6]
    b1 = a1 / ((a1**2).sum(-1, keepdims=True) ** 0.5).clip(1e-8)
    a2 = a2 - (b1 * a2).sum(-1, keepdims=True) * b1
    b2 = a2 / ((a2**2).sum(-1, keepdims=True) ** 0.5).clip(1e-8)
    b3 = xp.cross(b1, b2, axis=-1) if xp is np else xp.cross(b1, b2, dim=-1)
    return xp.stack([b1, b2, b3], -1)


def quat_to_rot6d(quat):
    return matrix_to_rot6d(quat_to_matrix(quat))


def rot6d_to_quat(rot6d) -> np.ndarray:
    return matrix_to_quat(rot6d_to_matrix(np.asarray(rot6d, dtype=np.float64)))


def slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions (w, x, y, z), shortest arc."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    dot = float(np.dot(q0, q1))
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - t) * theta) * q0 + np.sin(t * theta) * q1) / np.sin(theta)
