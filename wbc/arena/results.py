"""`ResultsStore`: a results directory that never loses a finished trial.

Each finished trial is appended to ``trials.csv`` as one line and flushed to disk (fsync) before the next is
accepted, so a run killed at any moment keeps everything it finished; a line cut short by the kill is dropped when
the store is reopened. ``run.json`` holds the run's identity (`wbc.arena.identity.RunIdentity`: the resolved
configuration and scenario hash), package versions, git revision and what each controller is (its kind, a plug-in's
target and distribution version, the sha256 of every file it was built from: weights, an ONNX model and its external
data, an I/O or configuration file); reopening a directory for another run is refused, naming the fields that differ.
"""

from __future__ import annotations

import csv
import json
import os
import re
from pathlib import Path

from wbc.arena.identity import RunIdentity
from wbc.arena.record import TrialRecord
from wbc.errors import ResultsDirError
from wbc.provenance import provenance

__all__ = ["ResultsStore", "episode_path"]


def episode_path(out_dir: Path, controller: str, band: str, seed: int, index: int) -> Path:
    """Where a results directory keeps a trial's episode log (``wbc run --save-episodes``).

    A controller name that is not a plain word (``policy:runs/x/policy``) becomes one directory, its separators
    replaced by ``_``.
    """
    folder = re.sub(r"[^A-Za-z0-9._-]+", "_", controller)
    return Path(out_dir) / "episodes" / folder / f"{band}-s{seed}-t{index}.npz"


class ResultsStore:
    """A results directory.

    Args:
        out_dir: the directory (created if missing).
        identity: what the run is; when resuming, its JSON form must equal the stored one (``run.json``'s
            ``config``), which an earlier version may have written: unset options are absent from both.
        resume: continue a run already in `out_dir`; without it, a directory holding trials is refused.
        controllers: what each controller is, by name (`wbc.control.spec.ControllerSpec.provenance`: its kind, a
            plug-in's target and distribution version, the sha256 of every file it was built from), recorded in
            ``run.json`` beside the configuration.

    Raises:
        ResultsDirError: `out_dir` holds results and `resume` is off, or holds another run (the message names the
            fields that differ), or its ``run.json`` is unreadable.
        RecordError: its ``trials.csv`` has other columns or an unreadable row.

    Attributes:
        dir: the directory.
        identity: the run's identity, as given.
        environment: the package versions and git revision ``run.json`` records (`wbc.provenance.provenance`).
        records: the trials stored, in the order they finished.
    """

    def __init__(self, out_dir: Path, identity: RunIdentity, *, resume: bool,
                 controllers: dict[str, object] | None = None) -> None:
        self.dir = Path(out_dir)
        self.identity = identity
        config = identity.as_json()
        self.trials_path = self.dir / "trials.csv"
        self.run_path = self.dir / "run.json"
        self.dir.mkdir(parents=True, exist_ok=True)
        if self.trials_path.exists() and not resume:
            raise ResultsDirError(f"{self.dir}: already holds results; pass --resume to finish that run, or choose "
                                  "another --out")
        if resume and self.run_path.exists():
            # compared as JSON, not read back as a RunIdentity: a stored run of another kind or version is named
            # field by field as differing, not refused as malformed
            try:
                stored = json.loads(self.run_path.read_text(encoding="utf-8")).get("config")
            except (OSError, ValueError, AttributeError) as exc:
                raise ResultsDirError(f"{self.run_path}: unreadable run configuration ({type(exc).__name__}: {exc}); "
                                      "restore the file, or start afresh with another --out") from None
            if not isinstance(stored, dict):
                raise ResultsDirError(f"{self.run_path}: field config: missing or not an object; restore the file, "
                                      "or start afresh with another --out")
            if stored != config:
                diff = sorted(k for k in set(stored) | set(config) if stored.get(k) != config.get(k))
                raise ResultsDirError(f"{self.dir}: --resume with a different configuration (differs in: "
                                      f"{', '.join(diff)}); rerun with the original options or another --out")
        self.records: list[TrialRecord] = []
        if self.trials_path.exists():
            self.records = TrialRecord.read_csv(self.trials_path)
            # rewrite without a torn last line so appends start on a fresh line
            self._rewrite()
        else:
            with self.trials_path.open("w", encoding="utf-8", newline="") as f:
                csv.writer(f).writerow(TrialRecord.header())
        self.environment = provenance()  # what `run.json` records; the report shows the same, taken once
        run = {"config": config, "environment": self.environment}
        if controllers:
            run["controllers"] = controllers
        self.run_path.write_text(json.dumps(run, indent=2), encoding="utf-8")
        self._file = self.trials_path.open("a", encoding="utf-8", newline="")
        self._writer = csv.writer(self._file)

    def _rewrite(self) -> None:
        tmp = self.trials_path.with_suffix(".tmp")
        with tmp.open("w", encoding="utf-8", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(TrialRecord.header())
            writer.writerows(r.to_row() for r in self.records)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.trials_path)

    def done(self) -> set[tuple[str, str, int, int]]:
        """Keys (controller, band, seed, trial) already finished."""
        return {r.run_key for r in self.records}

    def append(self, record: TrialRecord) -> None:
        """Store one finished trial durably."""
        self._writer.writerow(record.to_row())
        self._file.flush()
        os.fsync(self._file.fileno())
        self.records.append(record)

    def close(self) -> None:
        """Close the trials file."""
        self._file.close()
