"""`finish_results`: the one function that completes a results directory, for simulated runs and hardware trials.

A results directory is written in two parts. While trials play, the results store (`wbc.arena.results.ResultsStore`)
appends each record to ``trials.csv`` and keeps ``run.json``. When they are done, `finish_results` writes what is
derived from the records: ``summary.json`` (`wbc.arena.summary.Summary.to_json`), ``failures.json`` (where each
controller fails, when given) and ``report.md`` with its plots. ``wbc compare`` and ``wbc hw run`` both end here, so
the two kinds of directory hold the same files in the same form. Each file is written whole or not at all
(`wbc.output_files`): an interrupted finish leaves the previous one's files, and ``--resume`` writes them again.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wbc.arena.report import write_report
from wbc.arena.results import unwritable
from wbc.arena.summary import Summary
from wbc.arena.trial_record import TrialRecord
from wbc.output_files import write_text

__all__ = ["finish_results"]


def finish_results(out_dir: str | Path, summary: Summary, records: Sequence[TrialRecord], meta: Mapping[str, Any],
                   *, sections: Sequence[tuple[str, Sequence[str]]] = (), failures: Mapping[str, Any] | None = None,
                   curve: Mapping[str, Any] | None = None, scenario: str | None = None,
                   resumable: bool = True) -> list[Path]:
    """Write ``summary.json``, ``failures.json`` (when `failures` is given) and the report into `out_dir`.

    Args:
        out_dir: the results directory (it exists: the results store made it).
        summary: the records' summary (`wbc.arena.report.summarize`).
        records: the records summarised (for the report's per-trial plots).
        meta: the run information the report lists.
        sections: more report sections (a hardware trial's timing, safety events and operator actions).
        failures: where each controller fails (`wbc.arena.breakdown.breakdown`), None for none.
        curve: the push-recovery curve (`wbc.arena.breakdown.recovery_curve`), None for none.
        scenario: the scenario with its version (``push v2``), as the plots' titles name it; None: the summary's
            scenario name.
        resumable: the run can be resumed (``--resume``), as the message of a file that cannot be written then says;
            off: a hardware trial.

    Returns:
        The files written: ``summary.json``, ``failures.json`` (if any), ``report.md``, then the plots.

    Raises:
        ResultsDirError: a file could not be written (a full disk, a quota, no permission; `unwritable`: the message
            names it, and says that ``--resume`` writes them all again).
    """
    out = Path(out_dir)
    written = [out / "summary.json"]
    try:
        write_text(written[0], json.dumps(summary.to_json(), indent=2))
        if failures is not None:
            written.append(out / "failures.json")
            write_text(written[-1], json.dumps({"breakdown": failures, "push_recovery": curve}, indent=2))
        return [*written, *write_report(out, summary, records, meta, sections=sections, failures=failures,
                                        curve=curve, scenario=scenario)]
    except OSError as exc:
        raise unwritable(exc.filename or out, exc, out, stored=len(records), resumable=resumable) from exc
