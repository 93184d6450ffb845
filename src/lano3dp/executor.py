"""A graph of cells (collect, train, evaluate) run in this process, in a process pool, or on a Ray cluster.

A graph of work (a benchmark's datasets, trainings and evaluations) is written as a list of `Cell`s: small
picklable descriptions of one unit of work each (its kind, its JSON-able parameters, the cells whose outputs it
reads, the file or folder it writes, the CPU cores it keeps busy). An executor runs the cells a graph still
needs, each after its inputs:

    LocalExecutor(workers=1)    in this process, in dependency order
    LocalExecutor(workers=N)    a pool of spawned processes, at most N cores' worth of cells at a time
    RayExecutor(address=None)   one Ray task per cell with `num_cpus` declared; address None starts a local
                                instance bound to 127.0.0.1 (usage statistics off), "auto" or "ray://host:10001"
                                joins a cluster

Cells write into a shared work folder and every kind knows when its output is complete (`CellKind.done`), so a
re-run, by either executor, skips what is done: what makes a cluster run resumable is the folder, not the
engine. On a cluster that folder must be on a filesystem every node sees.

The built-in kinds wrap `lano3dp.pipeline`'s stages; the simulator and torch are imported only when a cell
runs. Ray is an optional extra (`pip install 'lano3dp[ray]'`), imported only by `RayExecutor`.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from lano3dp.errors import Lano3dpError

Log = Callable[[str], None]

RAY_INSTALL_HINT = "the Ray executor needs the optional extra: pip install 'lano3dp[ray]'"
# Environment a cell's process needs whatever started it (a Ray worker on another node inherits nothing).
_CELL_ENV = ("MUJOCO_GL", "OMP_NUM_THREADS", "HF_HUB_OFFLINE", "PYOPENGL_PLATFORM")


class GraphError(Lano3dpError, ValueError):
    """A graph is malformed: a repeated name, an input that is no cell, a cycle, an unknown kind."""


class CellFailedError(Lano3dpError, RuntimeError):
    """A cell raised; `name` is the cell, `details` its traceback (from whichever process ran it)."""

    def __init__(self, name: str, details: str):
        self.name, self.details = name, details
        super().__init__(f"cell {name!r} failed:\n{details}")

    def __reduce__(self):  # raised in a pool or Ray worker, re-raised here
        return type(self), (self.name, self.details)


class RayNotInstalledError(Lano3dpError, ImportError):
    """`--executor ray` without the extra installed."""

    def __init__(self):
        super().__init__(RAY_INSTALL_HINT)


@dataclass(frozen=True)
class Cell:
    """One unit of work of a graph.

    Attributes:
        name: unique within its graph, e.g. "train open_drawer objects/seed0".
        kind: a key of the executor's kinds ("collect", "train", "eval", or a caller's own).
        params: the kind's arguments, JSON-able (so a graph can be printed, saved and compared).
        output: the file or folder the cell writes, in the shared work folder.
        inputs: names of the cells whose outputs this one reads; it runs after them.
        cpus: CPU cores it keeps busy: Ray's num_cpus, a local pool's share.
    """

    name: str
    kind: str
    params: Mapping[str, Any] = field(default_factory=dict)
    output: str = ""
    inputs: tuple[str, ...] = ()
    cpus: int = 1


class CellKind(NamedTuple):
    """How to run one kind of cell, and how to tell that a cell of it has nothing left to do.

    Both are module-level functions (or other picklables): a process pool or a Ray worker receives them with
    the cell. `done` is asked by the driver, so the work folder must be readable there too.
    """

    run: Callable[[Cell], Any]
    done: Callable[[Cell], bool]


class GraphRun(NamedTuple):
    """What an executor did: the cells it ran and those it found done, each in the order it settled them."""

    executed: tuple[str, ...]
    skipped: tuple[str, ...]


def ordered(cells: Sequence[Cell], kinds: Mapping[str, CellKind] | None = None) -> list[Cell]:
    """The cells in an order where every cell comes after its inputs (stable otherwise); raises GraphError."""
    by_name: dict[str, Cell] = {}
    for cell in cells:
        if cell.name in by_name:
            raise GraphError(f"two cells are named {cell.name!r}")
        if kinds is not None and cell.kind not in kinds:
            raise GraphError(f"cell {cell.name!r} has kind {cell.kind!r}; known kinds: {sorted(kinds)}")
        by_name[cell.name] = cell
    for cell in cells:
        missing = [name for name in cell.inputs if name not in by_name]
        if missing:
            raise GraphError(f"cell {cell.name!r} reads {missing}, which are not cells of the graph")
    order, state = [], {}  # state: 1 visiting, 2 placed

    def visit(cell: Cell, path: tuple[str, ...]) -> None:
        if state.get(cell.name) == 2:
            return
        if state.get(cell.name) == 1:
            raise GraphError(f"the graph has a cycle: {' -> '.join((*path, cell.name))}")
        state[cell.name] = 1
        for name in cell.inputs:
            visit(by_name[name], (*path, cell.name))
        state[cell.name] = 2
        order.append(cell)

    for cell in cells:
        visit(cell, ())
    return order


def describe(cells: Sequence[Cell]) -> str:
    """One line per cell (kind, name, CPUs, inputs), in dependency order: the plan of a run."""
    lines = []
    for cell in ordered(cells):
        after = f" after {', '.join(cell.inputs)}" if cell.inputs else ""
        lines.append(f"{cell.kind:8s} {cell.name} [{cell.cpus} cpu]{after}")
    return "\n".join(lines)


def _quiet(_: str) -> None:
    pass


def _plan(cells: Sequence[Cell], kinds: Mapping[str, CellKind] | None,
          log: Log) -> tuple[Mapping[str, CellKind], list[Cell], list[str]]:
    """(kinds, the cells to run in dependency order, the names of those already done): every executor's start."""
    kinds = BUILTIN_KINDS if kinds is None else kinds
    order = ordered(cells, kinds)
    skipped = [cell.name for cell in order if kinds[cell.kind].done(cell)]
    todo = [cell for cell in order if cell.name not in skipped]
    log(f"graph: {len(todo)} cells to run, {len(skipped)} done already")
    return kinds, todo, skipped


def _execute(cell: Cell, kind: CellKind, env: Mapping[str, str] | None = None) -> str:
    """Run one cell (in whatever process the executor chose); returns its name or raises CellFailedError."""
    for key, value in (env or {}).items():
        os.environ.setdefault(key, value)
    try:
        kind.run(cell)
    except Exception as error:
        raise CellFailedError(cell.name, traceback.format_exc()) from error
    return cell.name


def _cell_env() -> dict[str, str]:
    return {key: os.environ[key] for key in _CELL_ENV if key in os.environ}


# ---- local -----------------------------------------------------------------------------------------
class LocalExecutor:
    """Cells in this process (workers=1) or in a pool of spawned processes sharing `workers` cores.

    A pool runs a cell once its inputs are done, as many at a time as their `cpus` fit in `workers` (a cell
    needing more than `workers` runs alone). The first failure stops new cells from starting; those running
    finish, then CellFailedError is raised.
    """

    def __init__(self, workers: int = 1):
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers

    def run(self, cells: Sequence[Cell], kinds: Mapping[str, CellKind] | None = None, *,
            log: Log = _quiet) -> GraphRun:
        kinds, todo, skipped = _plan(cells, kinds, log)
        if self.workers == 1:
            executed = []
            for cell in todo:
                log(f"cell: {cell.name}")
                executed.append(_execute(cell, kinds[cell.kind]))
            return GraphRun(tuple(executed), tuple(skipped))
        return GraphRun(self._pool(todo, set(skipped), kinds, log), tuple(skipped))

    def _pool(self, todo: list[Cell], finished: set[str], kinds: Mapping[str, CellKind], log: Log) -> tuple[str, ...]:
        import multiprocessing as mp
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        executed: list[str] = []
        waiting, running, failure = list(todo), {}, None
        env = _cell_env()
        with ProcessPoolExecutor(self.workers, mp_context=mp.get_context("spawn")) as pool:
            while waiting or running:
                busy = sum(min(cell.cpus, self.workers) for cell in running.values())
                for cell in list(waiting):
                    if failure is not None:
                        break
                    need = min(cell.cpus, self.workers)
                    if all(name in finished for name in cell.inputs) and busy + need <= self.workers:
                        log(f"cell: {cell.name}")
                        running[pool.submit(_execute, cell, kinds[cell.kind], env)] = cell
                        waiting.remove(cell)
                        busy += need
                if not running:
                    break
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in done:
                    cell = running.pop(future)
                    try:
                        future.result()
                    except CellFailedError as error:
                        failure = failure or error
                        continue
                    except Exception as error:  # the process died, or the cell could not be pickled
                        failure = failure or CellFailedError(cell.name, repr(error))
                        continue
                    finished.add(cell.name)
                    executed.append(cell.name)
        if failure is not None:
            raise failure
        return tuple(executed)


# ---- ray -------------------------------------------------------------------------------------------
def import_ray(*, local: bool = False):
    """`ray`, after switching its usage statistics off; RayNotInstalledError (with how to install) if absent.

    `local`: this process will start a single-node instance (see `start_ray`); set before ray's first import.
    """
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    if local:
        os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    try:
        import ray
    except ImportError:
        raise RayNotInstalledError() from None
    return ray


def start_ray(address: str | None = None, *, num_cpus: int | None = None,
              object_store_memory: int | None = 256 * 1024**2) -> bool:
    """Connect to Ray: `address` None starts a local instance on 127.0.0.1; else join that cluster.

    Returns whether this call started (or joined) Ray, i.e. whether the caller should shut it down. A Ray
    already initialised in this process is used as it is.

    A local instance listens on 127.0.0.1 only: Ray 2.60 maps a `_node_ip_address` of 127.0.0.1 to the
    machine's routable address unless it runs in its single-node mode (RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0,
    the mode it uses on laptops), which is set here for local instances; a node that still comes up on
    another address is shut down and reported.
    """
    ray = import_ray(local=address is None)
    if ray.is_initialized():
        return False
    if address is not None:
        ray.init(address=address)
        return True
    from ray._private import ray_constants  # a ray imported before import_ray(local=True) read the variable

    previous, ray_constants.ENABLE_RAY_CLUSTER = ray_constants.ENABLE_RAY_CLUSTER, False
    try:
        context = ray.init(num_cpus=num_cpus, _node_ip_address="127.0.0.1", include_dashboard=False,
                           object_store_memory=object_store_memory)
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = previous
    node_ip = context.address_info.get("node_ip_address")
    if node_ip != "127.0.0.1":
        ray.shutdown()
        raise Lano3dpError(f"the local Ray instance came up on {node_ip}, not 127.0.0.1; start one yourself "
                           "(ray start --head --node-ip-address 127.0.0.1) and pass --ray-address")
    return True


class RayExecutor:
    """Each cell still to do is one Ray task with `num_cpus=cell.cpus`, scheduled after its inputs' tasks.

    Args:
        address: None starts (and at the end stops) a local instance bound to 127.0.0.1; "auto" joins the
            cluster `ray start` made on this node; "ray://host:10001" joins one through Ray Client. A Ray that
            this process initialised already is used as it is.
        num_cpus: CPUs of a local instance (None: all of this machine's).

    Every node must have lano3dp installed and see the work folder at the same path.
    """

    def __init__(self, address: str | None = None, *, num_cpus: int | None = None):
        self.address, self.num_cpus = address, num_cpus
        import_ray(local=address is None)  # fail now, with the install line, rather than after planning a graph

    def run(self, cells: Sequence[Cell], kinds: Mapping[str, CellKind] | None = None, *,
            log: Log = _quiet) -> GraphRun:
        kinds, todo, skipped = _plan(cells, kinds, log)
        if not todo:
            return GraphRun((), tuple(skipped))
        ray = import_ray(local=self.address is None)
        started = start_ray(self.address, num_cpus=self.num_cpus)
        try:
            return GraphRun(self._submit(ray, todo, kinds, log), tuple(skipped))
        finally:
            if started:
                ray.shutdown()

    @staticmethod
    def _submit(ray, todo: list[Cell], kinds: Mapping[str, CellKind], log: Log) -> tuple[str, ...]:
        task = ray.remote(_ray_execute)
        env = _cell_env()
        refs: dict[str, Any] = {}
        for cell in todo:  # dependency order: an input's ref exists before its readers are submitted
            after = [refs[name] for name in cell.inputs if name in refs]
            # Ray retries a task whose worker died (a lost node); safe, since a cell resumes from its folder
            refs[cell.name] = task.options(num_cpus=cell.cpus, name=cell.name).remote(cell, kinds[cell.kind], env,
                                                                                     *after)
        names = {ref: name for name, ref in refs.items()}
        executed, pending = [], list(refs.values())
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            try:
                executed.append(ray.get(ready[0]))
            except Exception as error:  # RayTaskError wrapping CellFailedError, or a lost worker
                for ref in pending:
                    ray.cancel(ref)
                cause = getattr(error, "cause", None)
                if isinstance(cause, CellFailedError):
                    raise CellFailedError(cause.name, cause.details) from None
                raise CellFailedError(names[ready[0]], str(error)) from None
            log(f"cell: {executed[-1]} done")
        return tuple(executed)


def _ray_execute(cell: Cell, kind: CellKind, env: Mapping[str, str], *inputs: str) -> str:
    """A Ray task: `inputs` are the names its input tasks returned (Ray runs it only after them)."""
    return _execute(cell, kind, env)


def make_executor(name: str, *, workers: int = 1, ray_address: str | None = None,
                  ray_cpus: int | None = None) -> LocalExecutor | RayExecutor:
    """The executor an option names: "local" (`workers` processes) or "ray"."""
    if name == "local":
        return LocalExecutor(workers)
    if name == "ray":
        return RayExecutor(ray_address, num_cpus=ray_cpus)
    raise ValueError(f"unknown executor {name!r}; choose 'local' or 'ray'")


# ---- the built-in kinds: pipeline's stages -------------------------------------------------------------
def collect_cell(name: str, task: str, episodes: int, out: str | Path, **options) -> Cell:
    """Scripted-expert demonstrations of `task` until `out` holds `episodes` (options: collect's, JSON-able)."""
    return Cell(name, "collect", {"task": task, "episodes": episodes, "out": str(out), "options": options},
                output=str(out))


def _run_collect(cell: Cell) -> None:
    from lano3dp.pipeline import collect_stage

    p = cell.params
    collect_stage(p["task"], p["episodes"], p["out"], log=print, progress=False, **p["options"])


def _collect_done(cell: Cell) -> bool:
    from lano3dp.pipeline import dataset_episodes

    return dataset_episodes(cell.params["out"]) >= cell.params["episodes"]


def train_cell(name: str, data: str | Path, run: str | Path, *, steps: int, policy: Mapping[str, Any],
               inputs: Iterable[str] = (), **options) -> Cell:
    """Train `run` on `data` for `steps` steps, one thread.

    `policy`: overrides of `train.policy_config_for_dataset` (obs_type, down_dims, ...); `options` go to
    `pipeline.train_stage` (batch_size, lr, ckpt_every, seed, val_ratio, ...). JSON-able, both.
    """
    return Cell(name, "train", {"data": str(data), "run": str(run), "steps": steps, "policy": dict(policy),
                                "options": options}, output=str(run), inputs=tuple(inputs))


def _run_train(cell: Cell) -> None:
    from lano3dp.pipeline import train_stage
    from lano3dp.train import policy_config_for_dataset

    p = cell.params
    policy = {key: tuple(value) if isinstance(value, list) else value for key, value in p["policy"].items()}
    config = policy_config_for_dataset(p["data"], **policy)
    train_stage(p["data"], p["run"], policy_config=config, steps=p["steps"], threads=cell.cpus, log=print,
                progress=False, **p["options"])


def _train_done(cell: Cell) -> bool:
    from lano3dp.policy.checkpoint import list_checkpoints

    saved = Path(cell.params["run"]) / "train_config.json"
    if not saved.exists():
        return False
    planned = json.loads(saved.read_text())
    if planned.get("steps") != cell.params["steps"]:
        return False  # train_stage will say the folder was started for another step count
    done = max((step for step, _ in list_checkpoints(Path(cell.params["run"]) / "checkpoints")), default=0)
    return done >= planned["steps"] or planned.get("extra", {}).get("stopped_by_budget_at") == done > 0


def eval_cell(name: str, config, *, inputs: Iterable[str] = ()) -> Cell:
    """Evaluate an `evaluation.EvalConfig` (its `out` is the cell's output); its workers are the cell's CPUs."""
    if not config.out:
        raise ValueError(f"eval cell {name!r} needs an EvalConfig with out: the file that marks it done")
    return Cell(name, "eval", config.to_dict(), output=config.out, inputs=tuple(inputs),
                cpus=config.workers)


def _eval_config(cell: Cell):
    from lano3dp.evaluation import EvalConfig

    return EvalConfig.from_dict(cell.params)


def _run_eval(cell: Cell) -> None:
    import torch

    from lano3dp.pipeline import eval_stage

    config = _eval_config(cell)
    if config.workers == 1:
        torch.set_num_threads(1)
    started = time.perf_counter()
    summary = eval_stage(config, command=f"lano3dp.executor cell {cell.name!r}")["summary"]
    print(f"{cell.name}: success {summary['success_rate']:.0%} over {summary['episodes']} episodes "
          f"({time.perf_counter() - started:.0f} s)", flush=True)


def _eval_done(cell: Cell) -> bool:
    from lano3dp.pipeline import cached_eval

    return cached_eval(_eval_config(cell)) is not None


BUILTIN_KINDS: dict[str, CellKind] = {
    "collect": CellKind(_run_collect, _collect_done),
    "train": CellKind(_run_train, _train_done),
    "eval": CellKind(_run_eval, _eval_done),
}
