"""`ControllerSettings`: what a plug-in controller was built with from its ``--controller-config`` file.

A run's ``run.json`` names each settings file by path and sha256 (`wbc.control.spec.ControllerSpec.provenance`);
these are the settings themselves: the file's table as given, and, from a controller that says them
(`wbc.control.protocol.HasSettings`), every setting it runs with, defaults and computed values filled in (the tail
MPC's ready pose when the file leaves it to `wbc.mpc.tail_controller.ready_pose`). ``run.json`` holds them under
``controllers.NAME.settings``, and the report's Run section lists each file with the keys it sets.

`identical_settings` finds the controllers of a run that would play the same trials bit for bit: the same class, arm
mode and resolved settings under two names (two labels given byte-identical files, a label with no file beside the
registry's ``mpc``), which add nothing but tests to the verdict's family.
"""

from __future__ import annotations

import datetime
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from wbc.control.plugin import PluginFactory
from wbc.control.protocol import Controller, HasSettings
from wbc.control.spec import ControllerSpec
from wbc.toml_lines import toml_keys

__all__ = ["ControllerSettings", "identical_settings"]


@dataclass(frozen=True, kw_only=True)
class ControllerSettings:
    """A plug-in controller's settings file, its table and the settings the controller runs with.

    Attributes:
        file: the ``--controller-config`` file, as given.
        table: its parsed table, as given.
        resolved: every setting the controller runs with (`HasSettings.settings`), or None for a controller that
            does not say them.
    """

    file: str
    table: Mapping[str, Any]
    resolved: Mapping[str, Any] | None

    @classmethod
    def of(cls, spec: ControllerSpec, ctrl: Controller) -> ControllerSettings | None:
        """The settings `ctrl`, built by `spec`, was given by a file; None for a controller built without one."""
        if not isinstance(spec.make, PluginFactory) or spec.make.config is None or spec.make.config_file is None:
            return None
        return cls(file=spec.make.config_file, table=spec.make.config,
                   resolved=ctrl.settings() if isinstance(ctrl, HasSettings) else None)

    def as_json(self) -> dict[str, Any]:
        """``run.json``'s ``controllers.NAME.settings``: ``table`` (TOML dates as ISO 8601 text) and ``resolved``."""
        return {"table": _json_safe(self.table), "resolved": _json_safe(self.resolved)}

    def report_line(self) -> str:
        """The file and the keys it sets, as the report's Run section lists them."""
        keys = toml_keys(self.table)
        return f"{self.file}: sets {', '.join(keys)}" if keys else f"{self.file}: sets nothing (the defaults)"


def identical_settings(built: Mapping[str, tuple[str, Controller]]) -> list[tuple[str, ...]]:
    """The groups of controllers that run one class with identical resolved settings on one arm mode.

    Args:
        built: each controller of a run, by name: (its arm mode, the controller built for the run's robot); those
            that do not say their settings (`HasSettings`) are never grouped.

    Returns:
        Each group of two names or more, in the order the names first appear in `built`.
    """
    groups: dict[tuple[str, str, str], list[str]] = {}
    for name, (arm_mode, ctrl) in built.items():
        if isinstance(ctrl, HasSettings):
            kind = f"{type(ctrl).__module__}.{type(ctrl).__qualname__}"
            key = (arm_mode, kind, json.dumps(_json_safe(ctrl.settings()), sort_keys=True))
            groups.setdefault(key, []).append(name)
    return [tuple(names) for names in groups.values() if len(names) > 1]


def _json_safe(value: Any) -> Any:
    """`value` with its mappings as dicts, its tuples as lists and TOML's dates and times as ISO 8601 text."""
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    return value
