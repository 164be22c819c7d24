"""What a resumed run's environment changed since the run began: compared, refused or noted, recorded, reported.

``run.json``'s ``environment`` is the one the run began under (`wbc.provenance.provenance`), kept on every
``--resume``. A resume under another one is compared with it field by field (`changes`):

- another version of a package that changes results (`wbc.provenance.RESULT_PACKAGES`: NumPy, MuJoCo, numba ...),
  installed both times, is refused (`refusal`): those versions are documented to change the last bits of a trial, the
  stored trials were played under the earlier one, and the earlier environment can always be installed again (the
  lock of the run's revision);
- anything else (the git revision or its uncommitted changes, the hash of the wbc package's files, the Python, the
  platform, the CPU, the lock's hash, a package installed or removed since) is a warning that names each change, old
  -> new (`warning`), and ``run.json`` records the resume under ``environment.resumes`` (`record`): the trials stored
  before it, what changed. A change of the code (`CODE_FIELDS`) makes the run one of two codes: the warning says so,
  and ``summary.json`` marks it (``mixed_environments``, `mixed`). Code
  cannot be told apart from a change that plays no part in a trial (a docs commit mid-study), so a study must stay
  resumable across both; the record and the report (`report_lines`) keep what a reader needs to judge it.

A field the stored environment does not hold (a ``run.json`` written before it was recorded) is not compared: what it
was is unknown.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wbc.errors import RecordError
from wbc.provenance import PACKAGES, RESULT_PACKAGES

__all__ = ["CODE_FIELDS", "Change", "changes", "check_stored", "mixed", "record", "refusal", "report_lines", "warning"]

_FIELDS = ("git_revision", "git_diff_sha256", "lock_sha256", "python", "platform")
"""The environment's single-valued fields compared, beside the packages and the CPU."""

_IF_RECORDED = ("wbc_sha256",)
"""Fields compared only where the stored environment holds them: a run begun before they were recorded does not."""

CODE_FIELDS = ("git_revision", "git_diff_sha256", "wbc_sha256")
"""The fields that name the code: a resume that changes one plays the rest of the run under another code."""

_NEWER = "cpu"
"""A field every environment this version writes holds: a stored one with it lists every package of `PACKAGES`
installed then, so a package it lacks was not installed; one without it recorded fewer packages."""


@dataclasses.dataclass(frozen=True)
class Change:
    """One field of the environment that differs from the run's start.

    Attributes:
        field: the field, as ``run.json`` names it (``packages.numpy``, ``git_revision``, ``cpu.flags`` ...).
        was: its value when the run began (None: absent, not installed).
        now: its value now (None: absent, not installed).
        refuses: the resume is refused for it (another version of a package that changes results).
    """

    field: str
    was: Any
    now: Any
    refuses: bool = False

    def text(self) -> str:
        """``field old -> new``, with ``none`` for an absent value."""
        if self.field == "cpu.flags" and isinstance(self.was, list) and isinstance(self.now, list):
            lost, gained = sorted(set(self.was) - set(self.now)), sorted(set(self.now) - set(self.was))
            parts = ([f"lost {' '.join(lost)}"] if lost else []) + ([f"gained {' '.join(gained)}"] if gained else [])
            return f"cpu.flags {'; '.join(parts)}"
        return f"{self.field} {_word(self.was)} -> {_word(self.now)}"


def _word(value: object) -> str:
    if value is None:
        return "none"
    if isinstance(value, list):
        return " ".join(map(str, value)) or "(none)"
    return str(value)


def check_stored(environment: Mapping[str, Any], source: Path) -> None:
    """Refuse a stored ``environment`` whose compared fields are not of their types (it was edited).

    Raises:
        RecordError: ``packages`` or ``cpu`` not an object, the CPU's ``flags`` not a list of strings or its
            ``model`` not a string, ``resumes`` not a list of objects; the message names the file and the field.
    """
    for key in ("packages", "cpu"):
        if key in environment and not isinstance(environment[key], dict):
            raise RecordError(f"{source}: field environment.{key}: expected an object, got {environment[key]!r}; "
                              "restore the file, or start afresh with another --out")
    cpu = environment.get("cpu") or {}
    flags = cpu.get("flags")
    if flags is not None and (not isinstance(flags, list) or not all(isinstance(f, str) for f in flags)):
        raise RecordError(f"{source}: field environment.cpu.flags: expected a list of strings, got {flags!r}; "
                          "restore the file, or start afresh with another --out")
    model = cpu.get("model")
    if model is not None and not isinstance(model, str):
        raise RecordError(f"{source}: field environment.cpu.model: expected a string, got {model!r}; "
                          "restore the file, or start afresh with another --out")
    resumes = environment.get("resumes", [])
    if not isinstance(resumes, list) or not all(isinstance(r, dict) for r in resumes):
        raise RecordError(f"{source}: field environment.resumes: expected a list of objects, got {resumes!r}; "
                          "restore the file, or start afresh with another --out")


def changes(start: Mapping[str, Any], now: Mapping[str, Any]) -> list[Change]:
    """What differs between the environment the run began under (`start`, as stored) and `now`, in a fixed order.

    The packages come first (`PACKAGES`' order, then any other the start recorded), then the CPU's model and flags,
    then `_FIELDS`. A field `start` does not hold is not compared (written before it was recorded).
    """
    out: list[Change] = []
    old, new = start.get("packages", {}), now.get("packages", {})
    complete = _NEWER in start
    for name in [*PACKAGES, *(n for n in old if n not in PACKAGES)]:
        was, is_ = old.get(name), new.get(name)
        if was == is_ or (was is None and not complete):
            continue
        out.append(Change(f"packages.{name}", was, is_,
                          refuses=name in RESULT_PACKAGES and was is not None and is_ is not None))
    if _NEWER in start:
        was_cpu, now_cpu = start.get("cpu") or {}, now.get("cpu") or {}
        for key in ("model", "flags"):
            if was_cpu.get(key) != now_cpu.get(key):
                out.append(Change(f"cpu.{key}", was_cpu.get(key), now_cpu.get(key)))
    for key in _FIELDS:
        if (key in start or (complete and key in now)) and start.get(key) != now.get(key):
            out.append(Change(key, start.get(key), now.get(key)))
    for key in _IF_RECORDED:
        if key in start and start.get(key) != now.get(key):
            out.append(Change(key, start.get(key), now.get(key)))
    return out


def refusal(run_json: Path, found: Sequence[Change], stored: int) -> str | None:
    """The refusal of a resume for the changes that refuse it (`Change.refuses`), None where none does."""
    refused = [c for c in found if c.refuses]
    if not refused:
        return None
    return (f"{run_json}: --resume under other versions of packages that change results ("
            + "; ".join(c.text() for c in refused)
            + f"; run.json field environment.packages): the {stored} stored trial(s) were played under the earlier "
            "ones, and a run mixes no two; install the versions the run began under (the lock of its revision: "
            "make test and make demo install requirements/wbc.lock into .venv), or start afresh with another --out")


def warning(run_json: Path, found: Sequence[Change], stored: int, *, diff_file: str | None = None) -> str:
    """The warning of a resume under another environment than the run began under, naming each change.

    Where the code changed (`CODE_FIELDS`) it says that the run now mixes two codes, and where that is recorded;
    `diff_file` is the file of the results directory that keeps this resume's uncommitted changes, if any.
    """
    code = any(c.field in CODE_FIELDS for c in found)
    kept = f"; {diff_file} keeps this resume's uncommitted changes" if diff_file else ""
    mixes = (f": the run now mixes trials played by two codes (the {stored} stored ones by the earlier), so its "
             "results hold for neither alone" if code else
             f": the {stored} stored trial(s) were played under the earlier one, so the results may not reproduce to "
             "the bit from either")
    return (f"wbc: warning: {run_json}: --resume under another environment than the run began under ("
            + "; ".join(c.text() for c in found)
            + f"){mixes}; run.json records this resume (environment.resumes), summary.json marks the run "
            f"(mixed_environments) and report.md says so{kept}")


def mixed(environment: Mapping[str, Any]) -> list[str] | None:
    """What changed at each resume under another environment, as ``summary.json``'s ``mixed_environments`` lists it.

    One line per resume (``after N trial(s): field old -> new; ...``); None for a run played under one environment.
    """
    resumes = environment.get("resumes") or []
    if not resumes:
        return None
    return [f"after {r.get('stored_trials')} trial(s): "
            + "; ".join(Change(f, c.get("was"), c.get("now")).text() for f, c in (r.get("changed") or {}).items()
                        if isinstance(c, Mapping)) for r in resumes]


def record(start: Mapping[str, Any], found: Sequence[Change], stored: int, *,
           diff_file: str | None = None) -> dict[str, Any]:
    """The environment ``run.json`` keeps: `start`, with this resume appended to its ``resumes`` when `found`.

    `diff_file`: the results directory's file that keeps this resume's uncommitted changes (``diff_file``), if any.
    """
    out = dict(start)
    if found:
        entry: dict[str, Any] = {"stored_trials": stored,
                                 "changed": {c.field: {"was": c.was, "now": c.now} for c in found}}
        if diff_file is not None:
            entry["diff_file"] = diff_file
        out["resumes"] = [*start.get("resumes", []), entry]
    return out


def report_lines(environment: Mapping[str, Any]) -> dict[str, str]:
    """The run section's lines of an environment (as ``run.json`` keeps it), in the report's words.

    The fields in the order recorded (``python``, ``platform``, ``git_revision`` ...), the CPU as its model and flags,
    the packages as ``name version`` pairs, and, for a run resumed under another environment, a line that says the
    results were played under more than one, and what each resume changed.
    """
    out: dict[str, str] = {}
    for key, value in environment.items():
        if key == "cpu" and isinstance(value, Mapping):
            flags = value.get("flags")
            shown = "unknown" if flags is None else " ".join(flags) or "none"
            out[key] = f"{value.get('model')} (flags: {shown})"
        elif key == "packages" and isinstance(value, Mapping):
            out[key] = ", ".join(f"{k} {v}" for k, v in value.items())
        elif key != "resumes":
            out[key] = str(value)
    resumes = environment.get("resumes") or []
    if resumes:
        each = []
        for r in resumes:
            changed = [Change(f, c.get("was"), c.get("now")).text() for f, c in (r.get("changed") or {}).items()
                       if isinstance(c, Mapping)]
            each.append(f"resumed with {r.get('stored_trials')} trial(s) stored: {'; '.join(changed)}")
        out["environments"] = ("MORE THAN ONE: the results were played under more than one environment (the one "
                               "above began the run); " + " | ".join(each))
    return out
