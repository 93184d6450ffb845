"""One JSON conversion for results, dataset attributes and training states."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from lano3dp.jsonio import to_jsonable, write_json


def test_numpy_torch_paths_and_tuples_become_plain_json():
    value = {1: (np.float32(0.5), np.arange(3)), "t": torch.tensor([[1.0, 2.0]]), "p": Path("a/b"), "s": {7}}
    assert to_jsonable(value) == {"1": [0.5, [0, 1, 2]], "t": [[1.0, 2.0]], "p": "a/b", "s": [7]}


def test_non_finite_floats_are_null_in_results_but_kept_in_states():
    value = {"nan": float("nan"), "inf": np.float64(np.inf), "x": 1.5}
    assert to_jsonable(value) == {"nan": None, "inf": None, "x": 1.5}
    kept = to_jsonable(value, finite=False)
    assert math.isnan(kept["nan"]) and kept["inf"] == math.inf


def test_an_unknown_object_is_refused_by_name():
    with pytest.raises(TypeError, match="object"):
        to_jsonable({"a": object()})


def test_write_json_is_strict_json_and_leaves_no_temporary(tmp_path):
    path = write_json(tmp_path / "deep" / "result.json", {"rate": np.float64("nan"), "n": np.int64(3)})
    assert json.loads(path.read_text(), parse_constant=pytest.fail) == {"rate": None, "n": 3}
    assert [p.name for p in path.parent.iterdir()] == ["result.json"]
