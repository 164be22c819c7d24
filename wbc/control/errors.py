"""Errors of the controller layer: plug-ins that cannot be loaded or built, ONNX policies, failed contract checks.

Each failure kind is its own class so that a caller (and a test) can tell them apart; every message names what was
asked for, what is wrong and what would be valid. They take a message only, so they pickle: a plug-in's factory runs
in pool and Ray workers, and its failure travels back to the parent as this same error.
"""

from __future__ import annotations

from wbc.errors import FileFieldError, WbcError

__all__ = [
    "ControllerCheckError",
    "OnnxIoError",
    "OnnxModelError",
    "PluginAmbiguousError",
    "PluginAttributeError",
    "PluginConfigError",
    "PluginContractError",
    "PluginError",
    "PluginFactoryError",
    "PluginImportError",
    "PluginNotFoundError",
]


class PluginError(WbcError):
    """A controller plug-in (``package.module:factory`` or a ``wbc.controllers`` entry point) cannot be used."""


class PluginNotFoundError(PluginError, LookupError):
    """The plug-in's module (or entry point) does not exist where it was looked for; the message lists where."""


class PluginAmbiguousError(PluginError, LookupError):
    """Several installed distributions declare an entry point of the name; the message names them and their targets."""


class PluginImportError(PluginError, ImportError):
    """The plug-in's module exists but importing it raised; the message gives the error and where it was raised."""


class PluginAttributeError(PluginError, AttributeError):
    """The plug-in's module has no such factory, or it is not callable; the message lists the module's factories."""


class PluginConfigError(PluginError, TypeError):
    """A configuration table was given to a controller that takes none, or the factory does not accept one."""


class PluginFactoryError(PluginError, RuntimeError):
    """The plug-in's factory raised while building the controller; the message gives the error and its location."""


class PluginContractError(PluginError, TypeError):
    """The factory returned something that is not a `wbc.control.Controller`; the message lists what it lacks."""


class OnnxIoError(FileFieldError):
    """An ONNX policy's I/O file (TOML) is missing, unreadable or invalid; ``path:line: [table] key: reason``."""


class OnnxModelError(WbcError, ValueError):
    """An ONNX model cannot be read, or does not fit its I/O file (input or output names, sizes, element types)."""


class ControllerCheckError(WbcError, AssertionError):
    """A controller failed `wbc.control.check_controller`; the message lists every failed check."""
