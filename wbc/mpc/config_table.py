"""The MPC controller built from a settings table: a ``--controller-config`` file for `MpcController`.

The registered ``mpc`` runs the defaults; to run other settings from a file, name this module's factory as a
plug-in and hand it the file::

    wbc compare mpc wbc.mpc.config_table:make --controller-config proxsuite.toml --scenario scenarios/push.toml

with ``proxsuite.toml``::

    [mpc]
    qp_solver = "proxsuite"   # the MPC's QP backend (wbc.mpc.qp_solvers.QP_SOLVERS)

The tail MPC (``mpc-tail``) takes its settings the same way through `make_tail`, the table's keys being the fields of
`wbc.mpc.tail_controller.TailControllerConfig` (``base`` the MPC controller's, ``tail`` the tail MPC's)::

    wbc compare mpc-tail wbc.mpc.config_table:make_tail --controller-config held.toml --scenario scenarios/push.toml

with ``held.toml`` the ablation that keeps all of it but the arm's motion::

    [tail]
    arm_moves = false

The tail controller sets some of the base controller's settings itself, so `make_tail` refuses them, naming each and
where its tail equivalent is: every key of ``[base.mpc]`` (the tail MPC's own are ``[tail]``'s: ``mu``, ``pyramid``,
the weights, ``horizon``, ``dt``; it solves with DAQP, so ``qp_solver`` has none), ``[base]`` ``arm_kp`` and
``arm_kd`` (the top-level ``arm_kp``, ``arm_kd``), ``replan_every`` (one MPC step of ``[tail] dt``, which must be a
whole number of control ticks) and ``use_arm_momentum`` (``[tail] arm_moves``). ``[base]`` edits the tail's default
base settings, whose yaw leash is the tail's 0.1 rad (``[base] velocity_ki = 2`` keeps it).

The table's keys are the fields of `MpcControllerConfig` (or `TailControllerConfig`); a field that is itself a
settings dataclass (``mpc``, ``gait``, ``footholds``, ``estimator``, ``wbc``, ``base``, ``tail``, ``observer``) takes
a sub-table of its own fields, a tuple a TOML array, an optional pose (``ready_q``) an array of numbers. Fields left
out keep their defaults. An unknown key, or a value of the wrong kind, is a `ConfigError` that names the key and lists
the valid ones; ranges are checked by the settings' own validation. Every message names the key as the file writes
it (``[mpc] horizon``, ``[base] yaw_leash``, a top-level ``ready_q``), the settings' own included. The plug-ins
drive the robot with its arm actuated (``use_arm_momentum = false`` holds the MPC's arm still,
``tail.arm_moves = false`` the tail MPC's).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, TypeVar

from wbc.errors import ConfigError
from wbc.mpc.controller import MpcController, MpcControllerConfig
from wbc.mpc.tail_controller import (
    OVERRIDDEN,
    OverriddenSettingError,
    TailControllerConfig,
    TailMpcController,
    check_not_overridden,
)
from wbc.robots.description import RobotDescription
from wbc.toml_lines import toml_key

__all__ = ["in_toml_terms", "make", "make_tail", "mpc_config_from_table", "tail_config_from_table"]

_Settings = TypeVar("_Settings")


def mpc_config_from_table(table: Mapping[str, Any]) -> MpcControllerConfig:
    """The MPC controller's settings: the defaults, with the table's values in place of theirs.

    Args:
        table: keys of `MpcControllerConfig`, sub-tables for its nested settings (see the module's docstring).

    Raises:
        ConfigError: an unknown key, a value of the wrong kind, or settings their own validation refuses.
    """
    return _replaced(MpcControllerConfig(), table, ())


def make(desc: RobotDescription, config: Mapping[str, Any] | None = None) -> MpcController:
    """The centroidal MPC controller with the settings of a ``--controller-config`` table (defaults without one)."""
    settings = mpc_config_from_table(config or {})
    try:
        return MpcController(desc, settings)
    except ConfigError as error:  # a setting this robot cannot take (a CoM above its straight legs ...)
        raise _reworded(error, in_toml_terms(str(error), settings)) from None


def tail_config_from_table(table: Mapping[str, Any]) -> TailControllerConfig:
    """The tail MPC controller's settings: the defaults, with the table's values in place of theirs.

    Raises:
        ConfigError: an unknown key, a value of the wrong kind, a ``base`` setting the tail controller sets itself
            (`wbc.mpc.tail_controller.OVERRIDDEN`: the message names each and where its tail equivalent is), or
            settings their own validation refuses.
    """
    base = table.get("base") if isinstance(table, Mapping) else None
    overridden: list[str] = []
    if isinstance(base, Mapping):
        mpc = base.get("mpc")
        given = [f"base.{key}" for key in base] + ([f"base.mpc.{key}" for key in mpc] if isinstance(mpc, Mapping)
                                                   else [])
        overridden = [name for name in given if name in OVERRIDDEN]
    try:
        config = _replaced(TailControllerConfig(), table, ())
    except ConfigError as error:  # the base's own message (its advice may not apply here), then why it is moot
        if not overridden or isinstance(error, OverriddenSettingError):
            raise
        try:
            check_not_overridden(overridden)
        except ConfigError as moot:
            raise ConfigError(f"{error}; besides, {moot}") from None
        raise
    check_not_overridden(overridden)
    return config


def make_tail(desc: RobotDescription, config: Mapping[str, Any] | None = None) -> TailMpcController:
    """The tail MPC controller (``mpc-tail``) with the settings of a ``--controller-config`` table."""
    settings = tail_config_from_table(config or {})
    try:
        return TailMpcController(desc, settings)
    except ConfigError as error:  # a setting this robot cannot take (a ready pose outside its arm's limits ...)
        raise _reworded(error, in_toml_terms(str(error), settings)) from None


def _replaced(default: _Settings, table: Mapping[str, Any], path: tuple[str, ...]) -> _Settings:
    """`default` with the table's values in place of its own, sub-tables into nested settings.

    `path` is the table's own in the file (``()`` for the file's top level, ``("base", "mpc")`` for ``[base.mpc]``),
    by which every message names the key it is about, as the file writes it.
    """
    fields = {f.name: getattr(default, f.name) for f in dataclasses.fields(default) if f.init}  # type: ignore[arg-type]
    if not isinstance(table, Mapping):
        name, where = (toml_key(path), f"in [{'.'.join(path)}]") if path else ("the settings", "at the top level")
        raise ConfigError(f"{name} must be a table of settings, got {table!r}; valid keys {where}: "
                          f"{', '.join(fields)}")
    changes: dict[str, Any] = {}
    for key, value in table.items():
        if key not in fields:
            where = f"in [{'.'.join(path)}]" if path else "at the top level"
            raise ConfigError(f"{toml_key((*path, key))}: unknown key; valid keys {where}: {', '.join(fields)}")
        changes[key] = _value(fields[key], value, (*path, key))
    try:
        return dataclasses.replace(default, **changes)  # type: ignore[type-var]
    except ConfigError as error:  # the settings' own validation, which names its fields by their classes
        raise _reworded(error, in_toml_terms(str(error), default, path)) from None


def _reworded(error: ConfigError, message: str) -> ConfigError:
    """`error` with `message`, of its own class (`OverriddenSettingError` stays one), else a plain `ConfigError`."""
    try:
        again = type(error)(message)
    except TypeError:  # a subclass whose constructor takes other arguments than a message
        return ConfigError(message)
    return again if str(again) == message else ConfigError(message)


def in_toml_terms(message: str, settings: Any, path: tuple[str, ...] = ()) -> str:
    """`message` of the settings' own validation with the field it begins with named as a settings file writes it.

    The settings name their fields by class (``MpcConfig.horizon must be ...``); a file names them by table
    (``[mpc] horizon must be ...``). `settings` is the settings the message is about, at `path` in the file; a
    message that begins with no field of them or of their nested settings is returned as it is.
    """
    for obj, where in _nested(settings, path):
        name = type(obj).__name__
        if message.startswith(f"{name}: ") and where:
            return f"[{'.'.join(where)}]: {message[len(name) + 2:]}"
        if not message.startswith(f"{name}."):
            continue
        head, _, rest = message[len(name) + 1:].partition(" ")
        keys = tuple(head.rstrip(":").split("."))
        if keys[0] in {f.name for f in dataclasses.fields(obj)}:
            return f"{toml_key((*where, *keys))}{':' if head.endswith(':') else ''} {rest}"
    return message


def _nested(settings: Any, path: tuple[str, ...]) -> list[tuple[Any, tuple[str, ...]]]:
    """`settings` and every settings dataclass nested in it, each with its table's path, outermost first."""
    out = [(settings, path)]
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            out += _nested(value, (*path, f.name))
    return out


def _value(default: Any, value: Any, path: tuple[str, ...]) -> Any:
    """`value` as the kind of `default` (a table into settings, an array into a tuple, an integer into a float)."""
    where = toml_key(path)
    if dataclasses.is_dataclass(default):
        return _replaced(default, value, path)
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or len(value) != len(default):
            raise ConfigError(f"{where} must be an array of {len(default)} values like {list(default)}, got {value!r}")
        return tuple(_value(d, v, (*path[:-1], f"{path[-1]}[{i}]"))
                     for i, (d, v) in enumerate(zip(default, value, strict=True)))
    if default is None:  # an optional setting (e.g. `TailControllerConfig.ready_q`): numbers, or an array of them
        if isinstance(value, list | tuple) and value and all(_is_number(v) for v in value):
            return tuple(float(v) for v in value)
        if _is_number(value):
            return float(value)
        raise ConfigError(f"{where} must be a number or an array of numbers, got {value!r}")
    if isinstance(default, bool) or isinstance(value, bool):
        if not (isinstance(default, bool) and isinstance(value, bool)):
            raise ConfigError(f"{where} must be {_kind(default)}, got {value!r}")
        return value
    if isinstance(default, float) and isinstance(value, int | float):
        return float(value)
    if type(value) is not type(default):
        raise ConfigError(f"{where} must be {_kind(default)}, got {value!r}")
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _kind(default: Any) -> str:
    kinds = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}
    return kinds.get(type(default), type(default).__name__)
