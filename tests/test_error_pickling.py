"""Every `WbcError` pickles: an error raised in a worker process (a bench's spawned process, an arena worker) reaches
the parent as itself, with its message and attributes, instead of breaking the pool that carries it back."""

from __future__ import annotations

import inspect
import pickle

import pytest

import wbc.control.errors
import wbc.errors
from wbc.errors import (
    FileFieldError,
    FrameError,
    IoProcessStopped,
    MissingExtraError,
    MpcProblemFileError,
    PacketError,
    PortBusyError,
    SerialPortError,
    TargetInUseError,
    UnknownNameError,
    WbcError,
)

# the arguments of each constructor that takes more than a message, keyed by the class that defines it
CONSTRUCTOR_ARGS: dict[type, tuple[tuple[object, ...], dict[str, object]]] = {
    UnknownNameError: (("controller", "mcp", ["mpc", "stand"]), {"where": "scenario 'turn'"}),
    FileFieldError: (("scenarios/turn.toml", "must be > 0"), {"line": 7, "field": "[[bands]] #2 vx"}),
    MissingExtraError: (("mujoco", "sim"), {}),
    MpcProblemFileError: (("problem.npz", ["H", "g"]), {}),
    FrameError: (("crc", "go1", "LowState", "crc 0x1234 != 0x4321"), {}),
    PortBusyError: (("127.0.0.1", 8007, "address in use"), {}),
    TargetInUseError: (("127.0.0.1", 8007, 4242), {}),
    PacketError: (("header", "starts with 00"), {}),
    SerialPortError: (("/dev/ttyUSB0", "unplugged"), {}),
    IoProcessStopped: (("SIGTERM",), {"connected": True}),
}


def _error_classes() -> list[type[WbcError]]:
    classes = {cls for module in (wbc.errors, wbc.control.errors)
               for _, cls in inspect.getmembers(module, inspect.isclass) if issubclass(cls, WbcError)}
    return sorted(classes, key=lambda cls: (cls.__module__, cls.__name__))


def _instance(cls: type[WbcError]) -> WbcError:
    """An instance of `cls`, built by the constructor it has (its own or inherited), with the arguments it takes."""
    owner = next(base for base in cls.__mro__ if "__init__" in vars(base))
    if owner in CONSTRUCTOR_ARGS:
        args, kwargs = CONSTRUCTOR_ARGS[owner]
        return cls(*args, **kwargs)
    assert not issubclass(owner, WbcError), f"{owner.__name__} has a constructor of its own: add it to the table"
    return cls(f"{cls.__name__} went wrong; do this instead")


@pytest.mark.parametrize("cls", _error_classes(), ids=lambda cls: cls.__name__)
def test_every_wbc_error_round_trips_through_pickle(cls):
    err = _instance(cls)
    again = pickle.loads(pickle.dumps(err))
    assert type(again) is cls
    assert str(again) == str(err)
    assert again.args == err.args
    assert vars(again) == vars(err)


def test_unknown_name_and_scenario_errors_keep_their_fields():
    again = pickle.loads(pickle.dumps(UnknownNameError("controller", "mcp", ["stand", "mpc"])))
    assert (again.kind, again.name, again.valid, again.suggestion) == ("controller", "mcp", ("mpc", "stand"), "mpc")
    assert str(again).startswith("unknown controller 'mcp'; did you mean 'mpc'?")
    scenario = pickle.loads(pickle.dumps(wbc.errors.ScenarioError("turn.toml", "must be > 0", line=3, field="[a] b")))
    assert (scenario.path, scenario.line, scenario.field, scenario.reason) == ("turn.toml", 3, "[a] b", "must be > 0")
    assert str(scenario) == "turn.toml:3: [a] b: must be > 0"
