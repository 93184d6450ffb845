"""Import a script of bench/ as a module (bench/ is no package), for the tests of its pure parts."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "bench"
if str(BENCH) not in sys.path:  # the scripts import their shared contract (bench/_contract.py) as a script would
    sys.path.insert(0, str(BENCH))


def load_bench(name: str):
    """bench/<name>.py as a freshly executed module."""
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses (and pickling) look their module up by name
    spec.loader.exec_module(module)
    return module
