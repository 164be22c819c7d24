"""`ControllerSettings`: what a plug-in controller was built with from its ``--controller-config`` file.

A run's ``run.json`` names each settings file by path and sha256 (`wbc.control.spec.ControllerSpec.provenance`);
these are the settings themselves: the file's table as given, and, from a controller that says them
(`wbc.control.protocol.HasSettings`), every setting it runs with, defaults and computed values filled in (the tail
MPC's ready pose when the file leaves it to `wbc.mpc.tail_controller.ready_pose`). ``run.json`` holds them under
``controllers.NAME.settings``, and the report's Run section lists each file with the keys it sets.
"""

from __future__ import annotations

import datetime
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from wbc.control.plugin import PluginFactory
from wbc.control.protocol import Controller, HasSettings
from wbc.control.spec import ControllerSpec
from wbc.toml_lines import toml_keys

__all__ = ["ControllerSettings"]


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


def _json_safe(value: Any) -> Any:
    """`value` with its mappings as dicts, its tuples as lists and TOML's dates and times as ISO 8601 text."""
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    return value
