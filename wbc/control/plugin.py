"""Controller plug-ins: a controller from outside `wbc`, named ``package.module:factory`` or by an entry point.

A name of the form ``package.module:factory`` is imported at the moment it is named (explicitly, by
`importlib.import_module`; nothing registers itself by being imported) and ``factory`` is called with the robot
description, and with the ``--controller-config`` table when one is given, to build a `Controller`::

    def make(desc: RobotDescription, config: dict | None = None) -> Controller: ...

The module is looked up on ``sys.path`` first, then in the working directory (as ``python -m`` would), so
``wbc compare examples.my_controller:make stand`` works from a checkout. ``factory`` may also be a `ControllerPlugin`,
which adds a summary and the robots and arm modes the controller claims (a plain factory claims every robot with its
arm actuated). Installed packages declare plug-ins as entry points of the ``wbc.controllers`` group, e.g. in their
``pyproject.toml``::

    [project.entry-points."wbc.controllers"]
    my-mpc = "my_package.controller:make"

and ``wbc controllers`` lists them with their summaries; the entry point's name is then a controller name.

What travels to pool and Ray workers is a `PluginFactory`: the ``module:factory`` text, the directory its package
was found in and the configuration table, all plain data; the worker imports the module itself (that directory put
on its ``sys.path`` if missing). Every failure is its own `wbc.control.errors.PluginError` subclass whose message
says what was asked for, what is wrong and what would be valid; a factory built from a ``--controller-config`` file
that refuses the file's settings with a `ConfigError` raises that error again, its message beginning with the file's
path, and its other ``ValueError`` or ``TypeError`` name the file too.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.metadata
import inspect
import os
import re
import sys
import traceback
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from wbc.control.errors import (
    PluginAttributeError,
    PluginConfigError,
    PluginContractError,
    PluginFactoryError,
    PluginImportError,
    PluginNotFoundError,
)
from wbc.control.protocol import Controller
from wbc.control.spec import ControllerSpec, PluginSource, SourceFile
from wbc.errors import CONTROLLER_ERRORS, ConfigError, FileFieldError, UnknownNameError
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.registry import ROBOTS
from wbc.scenario.toml_fields import read_toml

__all__ = [
    "LABEL_MAX",
    "LABEL_RULE",
    "PLUGIN_GROUP",
    "ControllerPlugin",
    "PluginFactory",
    "build_plugin",
    "ambiguity",
    "controller_problems",
    "declared_entry_points",
    "entry_point_target",
    "entry_points",
    "is_plugin_name",
    "label_problem",
    "load_plugin",
    "plugin_name_problem",
    "plugin_spec",
    "plugin_target",
    "read_controller_config",
]

PLUGIN_GROUP = "wbc.controllers"
"""The entry-point group installed packages declare their controllers in."""

_IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
_TARGET = re.compile(rf"^({_IDENT}(?:\.{_IDENT})*):({_IDENT}(?:\.{_IDENT})*)$")
_MEMBERS = ("rate_hz", "reset", "act", "counters")

LABEL_MAX = 40
"""The most characters a plug-in name's label (``package.module:factory@LABEL``) may have."""

LABEL_RULE = (f"a label is a letter or digit, then letters, digits, '_', '.' or '-', at most {LABEL_MAX} characters "
              "in all, e.g. package.module:factory@h12")
"""What a label may be, as the errors say it."""

_LABEL = re.compile(rf"[A-Za-z0-9][A-Za-z0-9_.-]{{0,{LABEL_MAX - 1}}}")


@dataclass(frozen=True, kw_only=True)
class ControllerPlugin:
    """What a plug-in's factory name may point to, to say more than "call me".

    Attributes:
        make: ``make(desc)`` or ``make(desc, config)`` builds the controller for a robot description (`config`: the
            ``--controller-config`` table, when one is given).
        summary: one line for ``wbc controllers`` and reports.
        arm_modes: the arm modes it can drive; the arena plays the first, the contract checker builds every one.
        robots: the robots it can drive (registry names), or None for every robot.
    """

    make: Callable[..., Controller]
    summary: str
    arm_modes: tuple[str, ...] = ("actuated",)
    robots: tuple[str, ...] | None = field(default=None)

    def __post_init__(self) -> None:
        if not callable(self.make):
            raise TypeError(f"ControllerPlugin.make must be callable, got {type(self.make).__name__}")
        modes = (self.arm_modes,) if isinstance(self.arm_modes, str) else tuple(self.arm_modes)
        if not modes:
            raise ValueError("ControllerPlugin.arm_modes must name at least one arm mode (none, locked, actuated)")
        for mode in modes:
            check_arm_mode(mode)
        object.__setattr__(self, "arm_modes", modes)
        if self.robots is not None:
            robots = (self.robots,) if isinstance(self.robots, str) else tuple(self.robots)
            for robot in robots:
                if robot not in ROBOTS:
                    raise UnknownNameError("robot", robot, tuple(ROBOTS))
            object.__setattr__(self, "robots", robots)


def is_plugin_name(name: str) -> bool:
    """Whether `name` has the form ``package.module:factory`` (no label: see `plugin_target`)."""
    return _TARGET.match(name) is not None


def plugin_target(name: str) -> str | None:
    """The ``package.module:factory`` a plug-in name imports, or None when `name` is not a plug-in name.

    A plug-in name is ``package.module:factory``, or that with a label, ``package.module:factory@LABEL``: the label
    distinguishes two settings of one plug-in in one run (``wbc compare pkg.mod:make@a pkg.mod:make@b``, each with
    its own ``--controller-config``); it is not imported, and the controller is known everywhere by the whole name.
    A label is a letter or digit, then letters, digits, ``_``, ``.`` or ``-``, at most `LABEL_MAX` characters.
    """
    target, at, label = name.partition("@")
    if not is_plugin_name(target) or (at and _LABEL.fullmatch(label) is None):
        return None
    return target


def label_problem(name: str, *, registry: Collection[str] = (), entry_points: Mapping[str, str] | None = None
                  ) -> str | None:
    """Why `name`, which holds an ``@``, is no controller name, or None when it holds none.

    Only a plug-in named by its ``package.module:factory`` takes a label; the registry's controllers and policy
    files have no settings to tell apart, so a label means nothing there, and an entry point is labelled through
    the ``package.module:factory`` it declares.

    Args:
        name: the name as given.
        registry: the registry's names.
        entry_points: the installed entry points' targets by name (None: none looked up).
    """
    if "@" not in name:
        return None
    base, _, label = name.partition("@")
    what = ("a label (NAME@LABEL) tells apart two settings of one plug-in, named package.module:factory@LABEL, "
            "each with its own --controller-config")
    if is_plugin_name(base):
        if "@" in label:
            flaw = f"it has {name.count('@')} '@'; one separates the plug-in from its label"
        elif not label:
            flaw = "nothing follows the '@'"
        elif len(label) > LABEL_MAX:
            flaw = f"its label {label!r} has {len(label)} characters"
        else:
            flaw = f"its label {label!r} is not one"
        return f"controller {name!r}: {flaw}; {LABEL_RULE}"
    if base in registry:
        return (f"controller {name!r}: {base} is the registry's, and {what}; the registry's controllers take no "
                f"settings, so a label means nothing there: name it {base!r}, once")
    target = (entry_points or {}).get(base)
    if target is not None:
        return (f"controller {name!r}: {base} is an entry point, and {what}; an entry point's name takes no label: "
                f"label the plug-in it declares, {target}@{label or 'LABEL'}")
    flaw = plugin_name_problem(base)  # a plug-in meant, but written wrong: what is wrong with it
    return (f"controller {name!r}: {base!r} is not a plug-in's package.module:factory, and {what} ({LABEL_RULE}); "
            "the registry's controllers, policy:PATH and onnx:PATH take no label" + (f". {flaw}" if flaw else ""))


_IDENT_ONLY = re.compile(_IDENT)


_FILE_FORMS = {".onnx": "onnx:", ".npz": "policy:", ".json": "policy:"}
"""Files a controller name may hold, by suffix, and the prefix that names them."""


def _name_flaw(name: str) -> tuple[str, str | None]:
    """What is wrong with `name` as ``package.module:factory``, and the name it most likely meant (or None)."""
    module, colon, factory = name.partition(":")
    suffix = "." + module.rpartition(".")[2].lower() if "." in module else ""
    if not colon and suffix in _FILE_FORMS:
        prefix = _FILE_FORMS[suffix]
        return f"it is a file, and a {suffix} file is named {prefix}PATH", f"{prefix}{name}"
    if "/" in module or "\\" in module or suffix == ".py":
        dotted = re.sub(r"\.py$", "", module).replace("\\", "/").strip("/").replace("/", ".")
        return (f"{module} is a file path; a plug-in names its module by its dotted import path, not its file (and "
                "a policy file is named policy:PATH, an ONNX model onnx:PATH)"), f"{dotted}:{factory}"
    if not colon:
        head, _, tail = name.rpartition(".")
        return "it has no colon between the module and the factory", f"{head}:{tail}" if suffix != ".toml" else None
    if name.count(":") > 1:
        return f"it has {name.count(':')} colons; one separates the module from the factory", re.sub(":+", ":", name)
    if "(" in factory or ")" in factory:
        return "it has parentheses: name the factory, do not call it", f"{module}:{factory.partition('(')[0]}"
    if not module.strip():
        return "nothing before the colon: name the module the factory is defined in", None
    if not factory.strip():
        return "nothing after the colon: name the factory, e.g. make", None
    bad = next((part for part in (*module.split("."), *factory.split(".")) if not _IDENT_ONLY.fullmatch(part)), None)
    if not bad:
        return "it has an empty part between dots, or a dot at an end", None
    return f"{bad!r} is not a Python identifier (letters, digits and underscores, not beginning with a digit)", None


def plugin_name_problem(name: str) -> str | None:
    """Why `name` is not a plug-in name though it looks like one was meant, or None.

    A name looks like a plug-in's when it holds a colon, a path separator or a dot (``mypkg.good.make``,
    ``mypkg/good.py:make``, ``mypkg.good:``, ``mypkg.good::make``, ``mypkg.good:make()``); the caller checks the
    other names first (the registry's, ``policy:PATH``, ``onnx:PATH``, entry points, which may hold dots).

    Returns:
        ``'NAME' is not a plug-in name: what is wrong; for a plug-in, write package.module:factory ...; did you mean
        ...?``, or None
        for a valid plug-in name and for a name with none of those characters.
    """
    if is_plugin_name(name) or not any(c in name for c in ":/\\."):
        return None
    flaw, meant = _name_flaw(name)
    valid = meant is not None and (is_plugin_name(meant) or meant.startswith(tuple(_FILE_FORMS.values())))
    hint = f"; did you mean {meant!r}?" if valid else ""
    return (f"{name!r} is not a plug-in name: {flaw}; for a plug-in, write package.module:factory (dotted module "
            f"path, a colon, the factory's name), e.g. examples.my_controller:make{hint}")


def _split(target: str) -> tuple[str, str]:
    match = _TARGET.match(target)
    if match is None:
        raise PluginNotFoundError(plugin_name_problem(target) or f"{target!r} is not a plug-in name: write "
                                  "package.module:factory (dotted module path, a colon, the factory's name), e.g. "
                                  "examples.my_controller:make")
    return match.group(1), match.group(2)


def _where(exc: BaseException) -> str:
    """``file:line`` of the innermost frame of `exc`'s traceback that is not this module's, or ''."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename) != Path(__file__)]
    if isinstance(exc, SyntaxError) and exc.filename:
        return f" at {exc.filename}:{exc.lineno}"
    return f" at {frames[-1].filename}:{frames[-1].lineno}" if frames else ""


def _describe(exc: BaseException) -> str:
    text = str(exc) if not isinstance(exc, SyntaxError) else (exc.msg or str(exc))
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _root_of(module: ModuleType) -> str | None:
    """The directory on ``sys.path`` that `module` was imported from (None for built-in or frozen modules)."""
    spec = module.__spec__
    if spec is None or not spec.has_location or not spec.origin:
        if spec is not None and spec.submodule_search_locations:  # a namespace package: its first portion
            return str(Path(list(spec.submodule_search_locations)[0]).parents[module.__name__.count(".")])
        return None
    path = Path(spec.origin).resolve()
    if path.name.startswith("__init__."):
        path = path.parent
    return str(path.parents[module.__name__.count(".")])


def _is_the_module(missing: str | None, module: str) -> bool:
    """Whether a `ModuleNotFoundError` for `missing` means `module` itself (or a package above it) is absent."""
    return missing is not None and (module == missing or module.startswith(missing + "."))


def _import_once(module: str) -> ModuleType:
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if not _is_the_module(exc.name, module):
            raise PluginImportError(
                f"importing {module} failed: {_describe(exc)}{_where(exc)}; the plug-in needs that module: install "
                "it into this environment") from exc
        whose = "" if exc.name == module else f" (the package of {module})"
        raise PluginNotFoundError(
            f"no module named {exc.name!r}{whose}; looked on sys.path and in the working "
            f"directory {os.getcwd()}. Valid plug-in names: package.module:factory of a module found there (e.g. "
            "examples.my_controller:make from a checkout's root), or an installed entry point of the "
            f"{PLUGIN_GROUP!r} group (`wbc controllers` lists them)") from exc
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001 (any error of the plug-in's own code, reported with its location)
        raise PluginImportError(f"importing {module} failed: {_describe(exc)}{_where(exc)}") from exc


def _import(module: str, root: str | None) -> ModuleType:
    """Import `module`: from `root` (put on ``sys.path`` if missing), else from ``sys.path``, else the working dir."""
    if root is not None and root not in sys.path:
        sys.path.insert(0, root)
    importlib.invalidate_caches()  # a module written after start-up (a test's, a notebook's) is found too
    try:
        return _import_once(module)
    except PluginNotFoundError:
        cwd = os.getcwd()
        if root is not None or cwd in sys.path or "" in sys.path:
            raise
    # as `python -m` would: the working directory's modules are importable (the console script's sys.path lacks it)
    sys.path.insert(0, cwd)
    try:
        return _import_once(module)
    except PluginNotFoundError:
        sys.path.remove(cwd)
        raise


def _factories(module: ModuleType) -> list[str]:
    """Public names of `module` that could be a factory: its own functions and classes, and ControllerPlugins."""
    out = []
    for name, value in vars(module).items():
        if name.startswith("_"):
            continue
        if isinstance(value, ControllerPlugin) or (
                callable(value) and getattr(value, "__module__", None) == module.__name__):
            out.append(name)
    return sorted(out)


def _attribute(module: ModuleType, attr: str, target: str) -> object:
    value: object = module
    for part in attr.split("."):
        if not hasattr(value, part):
            valid = _factories(module)
            close = difflib.get_close_matches(part, valid, n=1)
            raise PluginAttributeError(
                f"plug-in {target}: module {module.__name__} ({module.__file__}) has no attribute {attr!r}"
                + (f"; did you mean {close[0]!r}?" if close else "")
                + f" Factories defined there: {', '.join(valid) if valid else 'none'}")
        value = getattr(value, part)
    if not isinstance(value, ControllerPlugin) and not callable(value):
        valid = _factories(module)
        raise PluginAttributeError(
            f"plug-in {target}: {attr} is a {type(value).__name__}, not a factory (a callable taking the robot "
            f"description, or a wbc.control.ControllerPlugin); factories defined in {module.__name__}: "
            f"{', '.join(valid) if valid else 'none'}")
    return value


def _first_line(text: str | None) -> str:
    lines = [line.strip() for line in (text or "").strip().splitlines()]
    return lines[0] if lines else ""


def load_plugin(target: str, root: str | None = None) -> tuple[ControllerPlugin, str | None]:
    """Import a plug-in's module and find its factory.

    Args:
        target: ``package.module:factory`` (the factory may be a dotted attribute path).
        root: the directory the module was found in by an earlier look-up (a worker passes the parent's).

    Returns:
        The plug-in (a plain factory wrapped with its docstring's first line as summary, arm actuated, every robot)
        and the directory its top-level package was imported from.

    Raises:
        PluginNotFoundError: malformed name, or no such module.
        PluginImportError: importing the module raised (the message gives the error and its file:line).
        PluginAttributeError: no such attribute, or it is not callable (the message lists the module's factories).
    """
    module_name, attr = _split(target)
    module = _import(module_name, root)
    value = _attribute(module, attr, target)
    if isinstance(value, ControllerPlugin):
        plugin = value
    else:
        summary = _first_line(getattr(value, "__doc__", None)) or f"plug-in {target}"
        plugin = ControllerPlugin(make=value, summary=summary)  # type: ignore[arg-type]
    top = sys.modules[module_name.split(".")[0]]
    return plugin, _root_of(top) if root is None else root


def _accepts(make: Callable[..., Any], n: int) -> bool:
    """Whether `make` can be called with `n` positional arguments (True when its signature is unknown)."""
    try:
        inspect.signature(make).bind(*([None] * n))
    except TypeError:
        return False
    except ValueError:  # no signature (a builtin): find out by calling
        return True
    return True


def _check_signature(plugin: ControllerPlugin, target: str, config: Mapping[str, Any] | None) -> None:
    if config is not None and not _accepts(plugin.make, 2):
        raise PluginConfigError(
            f"plug-in {target} was given a --controller-config table, but its factory takes no config argument "
            f"(signature {_signature(plugin.make)}); give it a second parameter, make(desc, config=None), or drop "
            "--controller-config")
    if config is None and not _accepts(plugin.make, 1):
        raise PluginFactoryError(
            f"plug-in {target}: its factory cannot be called as factory(desc) (signature {_signature(plugin.make)}); "
            "a factory takes the robot description and, optionally, the --controller-config table: "
            "make(desc, config=None)")


def _signature(make: Callable[..., Any]) -> str:
    try:
        return f"{getattr(make, '__name__', 'factory')}{inspect.signature(make)}"
    except (TypeError, ValueError):
        return repr(make)


def controller_problems(obj: object) -> list[str]:
    """What keeps `obj` from being a `wbc.control.Controller` (empty when it is one).

    A class is never one, though the protocol's check accepts a class that defines the members: its methods would
    be called without an instance.
    """
    if isinstance(obj, type):
        return [f"it is the class {obj.__name__}, not an instance: return {obj.__name__}(...)"]
    if isinstance(obj, Controller):
        rate = obj.rate_hz
        if isinstance(rate, bool) or not isinstance(rate, int | float):
            return [f"rate_hz is a {type(rate).__name__}, not a number [Hz]"]
        return [f"{m}() is not callable" for m in _MEMBERS[1:] if not callable(getattr(obj, m))]
    return [f"it has no {m}" for m in _MEMBERS if not hasattr(obj, m)] or ["it does not satisfy the protocol"]


def build_plugin(plugin: ControllerPlugin, desc: RobotDescription, config: Mapping[str, Any] | None,
                 target: str, config_file: str | Path | None = None) -> Controller:
    """Call the plug-in's factory for `desc` (with `config` if given) and check that it built a `Controller`.

    Args:
        plugin: the plug-in (`load_plugin`).
        desc: the robot to build the controller for.
        config: the ``--controller-config`` table, or None.
        target: ``package.module:factory``, as the messages name the plug-in.
        config_file: the file `config` was read from, named by the errors its settings cause (None: none).

    Raises:
        ConfigError: the factory refused the settings of `config_file` with a `ConfigError` (the same class, its
            message prefixed with the file's path).
        PluginConfigError: a table was given and the factory takes none.
        PluginFactoryError: the factory has the wrong signature, or raised (the message gives the error and its
            file:line, and begins with `config_file` for a ``ValueError`` or ``TypeError``).
        PluginContractError: the result is not a `Controller` (the message lists what it lacks), or is a class
            rather than an instance of one.
    """
    _check_signature(plugin, target, config)
    try:
        ctrl = plugin.make(desc) if config is None else plugin.make(desc, dict(config))
    except CONTROLLER_ERRORS as exc:  # noqa: BLE001 (the plug-in's own failure, reported with its location)
        if config_file is not None and isinstance(exc, ConfigError):
            if str(exc).startswith(f"{config_file}: "):
                raise
            raise _in_file(exc, str(config_file)) from exc
        # a bad value or a value of the wrong kind most likely came from the file: the message starts with it
        origin = f"{config_file}: " if config_file is not None and isinstance(exc, ValueError | TypeError) else ""
        raise PluginFactoryError(f"{origin}plug-in {target} raised while building the controller for {desc.name} "
                                 f"(arm {desc.arm_mode}): {_describe(exc)}{_where(exc)}") from exc
    if isinstance(ctrl, type):
        raise PluginContractError(
            f"factory {target} returned the class {ctrl.__name__}, not an instance: return {ctrl.__name__}(...), "
            "the controller built for the robot description")
    problems = controller_problems(ctrl)
    if problems:
        raise PluginContractError(
            f"plug-in {target} returned a {type(ctrl).__name__}, which is not a wbc.control.Controller: "
            f"{'; '.join(problems)}. A controller has rate_hz [Hz], reset(), act(state, command) -> MotorCommand "
            "and counters() -> dict[str, int] (see wbc/control/protocol.py and examples/my_controller.py)")
    return ctrl


def _in_file(exc: ConfigError, path: str) -> ConfigError:
    """`exc`'s error again, its message prefixed with `path` (a plain `ConfigError` if its class cannot say it)."""
    message = f"{path}: {exc}"
    try:
        again = type(exc)(message)
    except TypeError:  # a subclass whose constructor takes other arguments than a message
        return ConfigError(message)
    return again if str(again) == message else ConfigError(message)


@dataclass(frozen=True)
class PluginFactory:
    """A plug-in, as it travels to a worker: plain data that imports and calls the factory when called.

    Attributes:
        target: ``package.module:factory``.
        root: the directory the parent imported the module's package from (put on a worker's ``sys.path``).
        config: the ``--controller-config`` table, or None.
        config_file: the file the table was read from, named in the errors its settings cause, or None.
    """

    target: str
    root: str | None
    config: Mapping[str, Any] | None = None
    config_file: str | None = None

    def __call__(self, desc: RobotDescription) -> Controller:
        """Build the controller for `desc` (importing the module here if this process has not yet)."""
        plugin, _ = load_plugin(self.target, self.root)
        return build_plugin(plugin, desc, self.config, self.target, self.config_file)


def read_controller_config(path: str | Path) -> dict[str, Any]:
    """The table of a ``--controller-config`` TOML file.

    Raises:
        FileFieldError: the file is missing, unreadable or not TOML (``path:line: reason``).
    """
    data, _ = read_toml(Path(path), str(path), FileFieldError,
                        missing="check the path given to --controller-config")
    return data


def declared_entry_points() -> dict[str, tuple[importlib.metadata.EntryPoint, ...]]:
    """Every installed ``wbc.controllers`` entry point by name, each name with every distribution's that declares it.

    Nothing is imported. A name with more than one entry point is ambiguous: no name of it is a controller, and
    `ambiguity` says why.
    """
    out: dict[str, list[importlib.metadata.EntryPoint]] = {}
    for ep in importlib.metadata.entry_points(group=PLUGIN_GROUP):
        out.setdefault(ep.name, []).append(ep)
    return {name: tuple(eps) for name, eps in out.items()}


def entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    """The installed ``wbc.controllers`` entry points by name, of names one distribution declares (none imported)."""
    return {name: eps[0] for name, eps in declared_entry_points().items() if len(eps) == 1}


def _declared_by(ep: importlib.metadata.EntryPoint) -> str:
    dist = _entry_point_distribution(ep)
    return f"{dist[0]} {dist[1]}" if dist is not None else "a distribution Python does not name"


def entry_point_target(ep: importlib.metadata.EntryPoint) -> str:
    """The ``package.module:factory`` an entry point names.

    Raises:
        PluginAttributeError: its value names a module and no factory (``"pkg.ctl"``), or is not of the form
            ``package.module:factory``; the message names the entry point, its distribution and the value to write.
    """
    value = ep.value.partition("[")[0].strip()  # less any extras: "pkg.ctl:make [gpu]"
    where = f"entry point {ep.name!r} of the {PLUGIN_GROUP!r} group in {_declared_by(ep)}"
    module, colon, factory = (part.strip() for part in value.partition(":"))
    if not colon and is_plugin_name(f"{module}:make"):
        raise PluginAttributeError(
            f"{where} points at module {module} with no factory; its value names the factory after a colon: "
            f'write "{module}:make" (with your factory\'s name) in that distribution\'s '
            f'[project.entry-points."{PLUGIN_GROUP}"] table')
    target = f"{module}:{factory}"
    if not is_plugin_name(target):
        raise PluginAttributeError(f"{where} has the value {ep.value!r}, which is not package.module:factory "
                                   f'({_name_flaw(value)[0]}); write "package.module:factory" (e.g. '
                                   '"my_package.controller:make") as its value')
    return target


def ambiguity(name: str, eps: tuple[importlib.metadata.EntryPoint, ...]) -> str:
    """Why the entry point name `name` that `eps` share names no controller: who declares it, and how to choose.

    Used as the message of `PluginAmbiguousError` and as the summary ``wbc controllers`` lists the name with.
    """
    who = ", ".join(f"{_declared_by(ep)} ({ep.value})" for ep in eps)
    return (f"controller {name!r} is ambiguous: {len(eps)} installed distributions declare a {PLUGIN_GROUP!r} entry "
            f"point of that name: {who}; name the one you mean by its package.module:factory (e.g. {eps[0].value}), "
            "or uninstall the others")


def _entry_point_distribution(ep: importlib.metadata.EntryPoint) -> tuple[str, str] | None:
    """(name, version) of the distribution that declares `ep`, or None when Python does not say."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return None
    return dist.metadata["Name"] or dist.name, dist.version


def plugin_spec(name: str, target: str, *, kind: str = "plug-in", config_file: str | Path | None = None,
                entry_point: importlib.metadata.EntryPoint | None = None) -> ControllerSpec:
    """Resolve a plug-in: import it, check its factory's signature, and make its spec.

    The spec's provenance (`ControllerSpec.provenance`) names the target, the module's file, the entry point and the
    distribution that provides the code (the entry point's own, else looked up from the module when asked), and
    the configuration file with its sha256 (hashed here, as it is read).

    Args:
        name: the name it is known by (``module:factory``, or an entry point's name).
        target: ``package.module:factory``.
        kind: ``plug-in`` or ``entry point``.
        config_file: a ``--controller-config`` TOML file, read here once.
        entry_point: the entry point `name` resolved to (None for a ``module:factory`` name).

    Raises:
        PluginError: any plug-in failure (see `load_plugin`, `build_plugin`).
        FileFieldError: the configuration file is unreadable.

    The spec's `make` raises what `build_plugin` does, naming `config_file` when its settings are refused.
    """
    config = read_controller_config(config_file) if config_file is not None else None
    plugin, root = load_plugin(target)
    _check_signature(plugin, target, config)
    module = sys.modules.get(_split(target)[0])
    source = PluginSource(target=target, module_file=getattr(module, "__file__", None),
                          entry_point=entry_point.name if entry_point is not None else None,
                          distribution=_entry_point_distribution(entry_point) if entry_point is not None else None)
    files = (SourceFile.hashed("config", config_file),) if config_file is not None else ()
    factory = PluginFactory(target, root, config, str(config_file) if config_file is not None else None)
    return ControllerSpec(name, plugin.arm_modes[0], factory, plugin.summary,
                          robots=plugin.robots, arm_modes=plugin.arm_modes, kind=kind,
                          config_file=str(config_file) if config_file is not None else None, files=files,
                          plugin=source)
