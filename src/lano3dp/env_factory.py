"""Which environment evaluation and `run` act in: the built-in simulator, or a user's own through a factory.

    --env my_robot.envs:make_env           a module path (importable from the current folder or sys.path)
    --env path/to/own_env.py:make_env      a file path
    EvalConfig(..., env="my_robot.envs:make_env")   or   EvalConfig(..., env=make_env)

The factory is called with keyword arguments, those its signature names (all of them with `**options`):

    task        the task name (EvalConfig.task, else the checkpoint's task)
    seed        the first episode's seed (each episode then calls env.reset(seed=...))
    variation   the evaluation's variation string, as given ("clean" by default)
    image_size  the camera size the checkpoint was trained on (pixels, square)
    render_rgb  whether RGB images are needed (image policies, videos)
    max_steps   the episode step limit asked for, or None

and returns an env meeting `lano3dp.sim.protocol.SimulatorProtocol`: `reset(seed=, options=) -> (obs, info)`,
`step(action (10,)) -> (obs, reward, terminated, truncated, info)`, where obs holds "state" (11,) and either
"frame" (an RGBDFrame), or "rgb"/"depth"/"intrinsics"/"cam_to_world", or the env has `frame()`
(`runtime.observe`). What only the simulator knows degrades: success is `info["success"]` when the env
reports it (and the results say when it never does), stages come from `info["stages"]` or are empty, obstacles
are the objects whose `instance_attributes` say `role: obstacle` or those named by --obstacles.

Without a factory (`env=None`) the built-in `TabletopEnv` is made by `builtin_env`, through the same path.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
import zlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lano3dp.errors import Lano3dpError

BUILTIN_LABEL = "the built-in simulator"
_FILE_MODULES: dict[str, Path] = {}  # module name given to a factory file -> that file
ENV_OPTIONS = ("task", "seed", "variation", "image_size", "render_rgb", "max_steps")
_PROTOCOL = ("an env needs reset(seed=, options=) -> (obs, info) and step(action) -> "
             "(obs, reward, terminated, truncated, info); see lano3dp.sim.protocol")


class EnvFactoryError(Lano3dpError, ValueError):
    """An --env factory cannot be found, cannot be called, or made something that is not an env."""


class EnvContractError(Lano3dpError, ValueError):
    """An env broke the protocol while running (a reset or step returned the wrong thing)."""


class NonFiniteObservationError(EnvContractError):
    """An env's observation after a step held NaN or inf: the episode ends with this as its error (a simulation
    that blew up), the evaluation goes on."""


def builtin_env(task: str, *, seed: int | None = None, variation: str = "clean", image_size: int = 128,
                render_rgb: bool = False, max_steps: int | None = None):
    """The built-in MuJoCo tabletop (`lano3dp.sim.TabletopEnv`) for a registered task; `seed` is unused (each
    episode resets with its own)."""
    from lano3dp.sim import TabletopEnv

    return TabletopEnv(task, variation=variation, image_size=image_size, render_rgb=render_rgb, max_steps=max_steps)


def is_builtin(spec: str | Callable | None) -> bool:
    return spec is None


def factory_name(factory: Callable) -> str:
    """A module-level callable -> "module:qualname", the form a config saves and a worker process re-imports.

    Raises:
        EnvFactoryError: a lambda, a function defined inside another, or anything not reachable by that name.
    """
    module, qualname = getattr(factory, "__module__", None), getattr(factory, "__qualname__", None)
    name = f"{_FILE_MODULES.get(module, module)}:{qualname}"
    if module is None or qualname is None or "<" in qualname:
        raise EnvFactoryError(f"env factory {factory!r} has no importable name (a lambda or a function defined "
                              "inside another); define it at module level or pass 'module:factory'")
    try:
        found = load_factory(name)
    except EnvFactoryError:
        found = None
    if found is not factory:
        raise EnvFactoryError(f"env factory {factory!r} is not reachable as {name}; define it at module level or "
                              "pass 'module:factory' or 'path/to/file.py:factory'")
    return name


def load_factory(spec: str) -> Callable:
    """'module:attr' or 'path/to/file.py:attr' (attr may be dotted: 'Class.create') -> the callable.

    Raises:
        EnvFactoryError: one line naming the spec and what is wrong (no colon, module or file not importable,
            attribute missing, not callable).
    """
    module_part, sep, attribute = str(spec).rpartition(":")
    if not sep or not module_part or not attribute:
        raise EnvFactoryError(f"--env {spec}: give module:factory or path/to/file.py:factory")
    module = _import(spec, module_part)
    value: Any = module
    for part in attribute.split("."):
        if not hasattr(value, part):
            offered = sorted(n for n, v in vars(module).items() if callable(v) and not n.startswith("_")
                             and getattr(v, "__module__", None) == module.__name__)
            raise EnvFactoryError(f"--env {spec}: {module_part} has no attribute {attribute!r}"
                                  + (f" (it defines: {', '.join(offered)})" if offered else ""))
        value = getattr(value, part)
    if not callable(value):
        raise EnvFactoryError(f"--env {spec}: {attribute} is {_describe(value)}, not a callable factory")
    return value


def _import(spec: str, module_part: str):
    is_file = module_part.endswith(".py") or "/" in module_part or "\\" in module_part
    try:
        if not is_file:
            return importlib.import_module(module_part)
        path = Path(module_part).expanduser().resolve()
        if not path.is_file():
            raise EnvFactoryError(f"--env {spec}: no file {module_part}")
        name = f"lano3dp_env_{path.stem}_{zlib.crc32(str(path).encode()):08x}"  # one module per file, re-used
        if name in sys.modules:
            return sys.modules[name]
        _FILE_MODULES[name] = path
        loader_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(loader_spec)
        sys.modules[name] = module  # before running it: dataclasses and pickling look the module up
        try:
            loader_spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
        return module
    except EnvFactoryError:
        raise
    except ModuleNotFoundError as error:
        if not is_file and error.name and module_part.startswith(error.name):
            raise EnvFactoryError(f"--env {spec}: no module named {module_part!r} (run from the folder that holds "
                                  "it, install it, or give path/to/file.py:factory)") from error
        raise EnvFactoryError(f"--env {spec}: importing {module_part} failed: {_one_line(error)}") from error
    except Exception as error:  # the user's module raised while importing
        raise EnvFactoryError(f"--env {spec}: importing {module_part} failed: {_one_line(error)}") from error


def make_env(spec: str | Callable | None, **options: Any):
    """Build the env a config names and wrap it in a `CheckedEnv`.

    Args:
        spec: None (the built-in simulator), 'module:factory', 'path/to/file.py:factory' or the callable itself.
        options: ENV_OPTIONS; each is passed when the factory's signature names it (all with **options).

    Raises:
        EnvFactoryError: the factory is missing, its call raised, or it returned no reset()/step().
    """
    unknown = set(options) - set(ENV_OPTIONS)
    if unknown:
        raise TypeError(f"unknown env options {sorted(unknown)}; known: {', '.join(ENV_OPTIONS)}")
    if is_builtin(spec):
        return CheckedEnv(builtin_env(**options), BUILTIN_LABEL)
    factory = load_factory(spec) if isinstance(spec, str) else spec
    label = spec if isinstance(spec, str) else getattr(factory, "__qualname__", repr(factory))
    accepted = accepted_options(factory, options)
    try:
        env = factory(**accepted)
    except Exception as error:
        arguments = ", ".join(f"{k}={v!r}" for k, v in accepted.items())
        raise EnvFactoryError(f"--env {label}: calling it with ({arguments}) raised {_one_line(error)}") from error
    missing = [name for name in ("reset", "step") if not callable(getattr(env, name, None))]
    if missing:
        raise EnvFactoryError(f"--env {label}: the factory returned {_describe(env)}, which has no "
                              f"{' and no '.join(f'{m}()' for m in missing)}; {_PROTOCOL}")
    return CheckedEnv(env, f"--env {label}")


def accepted_options(factory: Callable, options: Mapping[str, Any]) -> dict[str, Any]:
    """The options a factory's signature takes: all of them with **kwargs, else the ones it names."""
    try:
        parameters = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):  # a builtin or C callable without a signature: give it everything
        return dict(options)
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return dict(options)
    named = {p.name for p in parameters if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                                      inspect.Parameter.KEYWORD_ONLY)}
    return {key: value for key, value in options.items() if key in named}


class CheckedEnv:
    """An env with its replies checked against the protocol, and a note of whether it ever reports success.

    Checked: every reply's form (reset -> (obs, info), step -> 5 values, info a dict), every observation's
    "state" ((11,) real numbers, finite), and, on the first reset, the camera part of the observation (an
    RGBDFrame, or "rgb" (H, W, 3) uint8, "depth" (H, W), "intrinsics" (3, 3) and "cam_to_world" (4, 4) finite;
    or the env's frame()). A violation is an `EnvContractError` naming the env, the key and what was expected;
    non-finite values after a step are a `NonFiniteObservationError` (one of them), which ends that episode
    with a recorded error (`runtime.rollout`) rather than the evaluation.

    Every other attribute (frame, control_hz, max_steps, episode, ...) is the wrapped env's own, so code that
    asks for a simulator-only attribute with getattr(env, name, None) still sees whether the env has it.

    Attributes:
        env: the wrapped env.
        label: how errors name it ("--env own_env.py:make_env").
        reports_success: some reset or step info since the last reset held "success".
    """

    def __init__(self, env, label: str):
        self.env = env
        self.label = label
        self.reports_success = False
        self.steps = 0  # since the last reset, for messages
        self._frame_checked = label == BUILTIN_LABEL  # the built-in simulator's camera is trusted

    def __getattr__(self, name: str):
        if name == "env":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.env, name)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        reply = self.env.reset(seed=seed, options=options)
        if not (isinstance(reply, tuple) and len(reply) == 2):
            raise EnvContractError(f"{self.label}: reset() must return (obs, info), got {_describe(reply)}")
        obs, info = reply
        self.steps = 0
        self._check(obs, info, "reset()")
        if not self._frame_checked:
            self._check_frame(obs, "reset()")
            self._frame_checked = True
        self.reports_success = "success" in info
        return obs, info

    def step(self, action):
        reply = self.env.step(action)
        self.steps += 1
        if not (isinstance(reply, tuple) and len(reply) == 5):
            raise EnvContractError(f"{self.label}: step() must return (obs, reward, terminated, truncated, info), "
                                   f"got {_describe(reply)}")
        obs, info = reply[0], reply[4]
        self._check(obs, info, f"step {self.steps}")
        self.reports_success = self.reports_success or "success" in info
        return reply

    def _check(self, obs, info, call: str) -> None:
        if not isinstance(info, Mapping):
            raise EnvContractError(f"{self.label}: {call}'s info must be a dict, got {_describe(info)}")
        if isinstance(obs, Mapping):
            keys = set(obs)
        elif hasattr(obs, "state") and hasattr(obs, "frame"):
            self._check_state(obs.state, call)
            return
        else:
            raise EnvContractError(f"{self.label}: {call} returned {_describe(obs)} as observation; "
                                   "give a dict with 'state' (11,) and 'frame' (RGBDFrame) or rgb/depth/intrinsics/"
                                   "cam_to_world")
        if "state" not in keys:
            raise EnvContractError(f"{self.label}: {call}'s observation has no 'state' (11,: EE position, rotation "
                                   f"6D, gripper opening, grasp flag); its keys: {', '.join(sorted(map(str, keys)))}")
        self._check_state(obs["state"], call)
        if "frame" in keys or callable(getattr(self.env, "frame", None)):
            return
        missing = [k for k in ("depth", "intrinsics", "cam_to_world") if k not in keys]
        if missing:
            raise EnvContractError(f"{self.label}: {call}'s observation has no 'frame' and no "
                                   f"{', '.join(repr(m) for m in missing)}, and the env has no frame(); give an "
                                   "RGBDFrame as obs['frame'] or the camera's images and calibration")

    def _check_state(self, state, call: str) -> None:
        expected = "(11,) finite numbers: EE position (m), rotation 6D, gripper opening (m), grasp flag"
        try:
            array = np.asarray(state)
        except (ValueError, TypeError):
            array = None
        if array is None or array.dtype.kind not in "fiu" or array.shape != (11,):
            found = _describe(state) if array is None else f"{array.dtype} of shape {array.shape}"
            raise EnvContractError(f"{self.label}: {call}'s observation 'state' must be {expected}; got {found}")
        bad = np.flatnonzero(~np.isfinite(array.astype(np.float64)))
        if len(bad):
            error = NonFiniteObservationError if self.steps else EnvContractError
            raise error(f"{self.label}: {call}'s observation 'state' holds {array[bad[0]]} at index {bad[0]}; "
                        f"it must be {expected}")

    def _check_frame(self, obs, call: str) -> None:
        """The camera part of the first observation: keys, shapes, dtypes, a finite calibration."""
        from lano3dp.geometry import RGBDFrame
        from lano3dp.geometry.frame import observe

        if isinstance(obs, Mapping) and "frame" not in obs and not callable(getattr(self.env, "frame", None)):
            for key, shape, kinds in (("depth", ("H", "W"), "f"), ("intrinsics", (3, 3), "fi"),
                                      ("cam_to_world", (4, 4), "fi"), ("rgb", ("H", "W", 3), "u")):
                if key in obs:
                    self._check_array(obs[key], key, shape, kinds, call, finite=key in ("intrinsics", "cam_to_world"))
        try:
            frame, _ = observe(self.env, obs)
        except (KeyError, ValueError, TypeError) as error:
            raise EnvContractError(f"{self.label}: {call}'s observation does not make a camera frame: "
                                   f"{_one_line(error)}") from None
        if not isinstance(frame, RGBDFrame):
            raise EnvContractError(f"{self.label}: frame() returned {_describe(frame)}, not an RGBDFrame")
        self._check_array(frame.rgb, "frame rgb", ("H", "W", 3), "u", call, finite=False)  # PinholeCamera checks
        # its own calibration

    def _check_array(self, value, key: str, shape: tuple, kinds: str, call: str, *, finite: bool) -> None:
        names = {"f": "float", "i": "int", "u": "uint8"}  # depth: float metres (a uint16 in mm would pass as km)
        expected = f"({', '.join(map(str, shape))}{',' if len(shape) == 1 else ''}) " \
                   f"{' or '.join(names[k] for k in kinds)}{', finite' if finite else ''}"
        array = np.asarray(value) if isinstance(value, np.ndarray | list | tuple) or hasattr(value, "__array__") \
            else None
        ok = array is not None and array.ndim == len(shape) and array.dtype.kind in kinds and all(
            want in ("H", "W") or want == got for want, got in zip(shape, array.shape, strict=True)) and \
            (kinds != "u" or array.dtype == np.uint8)
        if not ok:
            found = _describe(value) if array is None else f"{array.dtype} of shape {array.shape}"
            raise EnvContractError(f"{self.label}: {call}'s observation {key!r} must be {expected}; got {found}")
        if finite and not np.isfinite(array).all():
            raise EnvContractError(f"{self.label}: {call}'s observation {key!r} must be {expected}; it holds "
                                   "NaN or inf")

    def close(self) -> None:
        close = getattr(self.env, "close", None)
        if callable(close):
            close()


def _describe(value: Any) -> str:
    if isinstance(value, tuple):
        return f"a tuple of {len(value)}"
    name = type(value).__name__
    return f"{'an' if name[:1].lower() in 'aeiou' else 'a'} {name}"


def _one_line(error: BaseException) -> str:
    text = " ".join(part.strip() for part in str(error).splitlines() if part.strip())
    return f"{type(error).__name__}: {text}" if text else type(error).__name__
