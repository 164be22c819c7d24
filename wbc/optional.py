"""Import optional dependencies with a message that names the extra to install."""

from __future__ import annotations

import importlib
from types import ModuleType

from wbc.errors import MissingExtraError

__all__ = ["EXTRAS", "require"]

EXTRAS = {
    "torch": "train",
    "rsl_rl": "train",
    "tensorboard": "train",
    "robot_interface": "hardware",
    "dynamixel_sdk": "hardware",
    "ray": "cluster",
    "onnxruntime": "onnx",
    "onnx": "train",
}
"""Module -> the ``pip install 'wbc[EXTRA]'`` extra that provides it."""


def require(module: str, extra: str | None = None) -> ModuleType:
    """Import `module`, or raise `MissingExtraError` naming the extra that installs it.

    Args:
        module: importable module name.
        extra: the extra to name (default: looked up in `EXTRAS`).
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(module, extra or EXTRAS.get(module, "dev")) from None
