"""Where a controller failed in its own code: the ``file:line`` that the arena and the contract checker both name.

The place named is the controller's own: the innermost frame of the exception's traceback that is not inside the
`wbc` package nor generated code (a dataclass's ``__init__``), preferring one inside the controller's own package
over a library it called (NumPy raising in a plug-in names the plug-in's line); for a failure with no frame of the
controller left on the traceback (a command refused after ``act`` returned), where the controller's method is defined.
A command the house refuses (`wbc.types.MotorCommand` raising on a NaN) is thus named at the plug-in's line that built
it, not at the house's line that checked it. A controller of `wbc`'s own classes has no place named: no line of the
house is the user's, and what its errors are about (an ONNX policy's network, a policy file) their messages name.
"""

from __future__ import annotations

import inspect
import sys
import traceback
from pathlib import Path

__all__ = ["failure_site", "own_frame"]

_WBC_DIR = Path(__file__).resolve().parent.parent
"""The `wbc` package's directory: frames inside it are the house's, not the controller's."""


def own_frame(exc: BaseException, owner: object = None) -> str | None:
    """``file:line`` of the innermost traceback frame of `exc` that is the controller's (module docstring).

    Args:
        exc: a raised exception (with its traceback).
        owner: the controller; frames inside its top-level package are preferred (None: no preference).

    Returns:
        The innermost frame inside `owner`'s package, else the innermost outside `wbc` and not generated code, else
        None.
    """
    home = _package_dir(owner)
    fallback = None
    for frame in reversed(traceback.extract_tb(exc.__traceback__)):
        if frame.filename.startswith("<"):
            continue
        path = Path(frame.filename).resolve()
        if path.is_relative_to(_WBC_DIR):
            continue
        if home is None or path.is_relative_to(home):
            return f"{frame.filename}:{frame.lineno}"
        fallback = fallback or f"{frame.filename}:{frame.lineno}"
    return fallback


def failure_site(exc: BaseException, controller: object, method: str) -> str | None:
    """``file:line`` of `controller`'s own code where `exc` arose while its `method` ran (module docstring).

    Args:
        exc: what the controller raised, or what refused its command.
        controller: the controller (built).
        method: the method that was running (``act`` for a command refused after ``act`` returned), whose
            definition is named when no frame of the controller is on the traceback.

    Returns:
        `own_frame`, else where `method` is defined, else None (a builtin, a C extension, a class of `wbc`'s own).
    """
    where = own_frame(exc, controller)
    return where if where is not None else _defined_at(controller, method)


def _package_dir(owner: object) -> Path | None:
    """The directory of `owner`'s class's top-level package (its file for a lone module); None if unknown or wbc."""
    if owner is None:
        return None
    top = sys.modules.get(type(owner).__module__.partition(".")[0])
    file = getattr(top, "__file__", None)
    if not file:
        return None
    path = Path(file).resolve()
    home = path.parent if path.name == "__init__.py" else path
    return None if home.is_relative_to(_WBC_DIR) else home


def _defined_at(controller: object, method: str) -> str | None:
    """``file:line`` where `controller`'s `method` is defined, or None (a builtin, a C extension, `wbc`'s code)."""
    fn = getattr(type(controller), method, None)
    try:
        file, line = inspect.getsourcefile(fn), inspect.getsourcelines(fn)[1]
    except (TypeError, OSError):
        return None
    return None if file is None or Path(file).resolve().is_relative_to(_WBC_DIR) else f"{file}:{line}"
