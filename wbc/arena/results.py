"""`ResultsStore`: a results directory that never loses a finished trial.

Each finished trial is appended to ``trials.csv`` as one line and flushed to disk (fsync) before the next is
accepted, so a run killed at any moment keeps everything it finished; a line cut short by the kill is dropped when
the store is reopened. ``run.json`` holds the resolved configuration, scenario hash, package versions and git
revision; reopening a directory for another configuration is refused.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
from pathlib import Path

from wbc.errors import WbcError
from wbc.provenance import provenance

__all__ = ["RECORD_FIELDS", "ResultsStore", "episode_path", "read_records"]

RECORD_FIELDS = (
    "controller", "scenario", "scenario_hash", "band", "seed", "trial",
    "success", "ttf", "fall_time_s", "vlin_err", "vang_err", "max_roll_deg", "max_pitch_deg", "energy_j",
    "arm_travel_rad", "push_force_n", "n_pushes", "vx_cmd", "vy_cmd", "yaw_rate_cmd", "friction", "payload_kg",
    "fallbacks", "wbc_failures", "debug_truth", "wall_s",
)
_INT_FIELDS = {"seed", "trial", "n_pushes", "fallbacks", "wbc_failures"}
_BOOL_FIELDS = {"success", "debug_truth"}
_STR_FIELDS = {"controller", "scenario", "scenario_hash", "band"}


def episode_path(out_dir: Path, controller: str, band: str, seed: int, index: int) -> Path:
    """Where a results directory keeps a trial's episode log (``wbc run --save-episodes``).

    A controller name that is not a plain word (``policy:runs/x/policy``) becomes one directory, its separators
    replaced by ``_``.
    """
    folder = re.sub(r"[^A-Za-z0-9._-]+", "_", controller)
    return Path(out_dir) / "episodes" / folder / f"{band}-s{seed}-t{index}.npz"


def _parse(row: dict[str, str]) -> dict[str, object]:
    out: dict[str, object] = {}
    for k, v in row.items():
        if k in _STR_FIELDS:
            out[k] = v
        elif k in _INT_FIELDS:
            out[k] = int(v)
        elif k in _BOOL_FIELDS:
            out[k] = v in ("True", "true", "1")
        else:
            out[k] = float(v)
    return out


def read_records(path: Path) -> list[dict[str, object]]:
    """Typed rows of a ``trials.csv``; a last line cut short by a crash is ignored."""
    text = path.read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    reader = csv.DictReader(io.StringIO(text))
    return [_parse(row) for row in reader if None not in row.values() and len(row) == len(RECORD_FIELDS)]


class ResultsStore:
    """A results directory.

    Args:
        out_dir: the directory (created if missing).
        config: the resolved run configuration; must equal the stored one when resuming.
        resume: continue a run already in `out_dir`; without it, a directory holding trials is refused.
    """

    def __init__(self, out_dir: Path, config: dict[str, object], *, resume: bool) -> None:
        self.dir = Path(out_dir)
        self.trials_path = self.dir / "trials.csv"
        self.run_path = self.dir / "run.json"
        self.dir.mkdir(parents=True, exist_ok=True)
        if self.trials_path.exists() and not resume:
            raise WbcError(f"{self.dir}: already holds results; pass --resume to finish that run, or choose "
                           "another --out")
        if resume and self.run_path.exists():
            stored = json.loads(self.run_path.read_text(encoding="utf-8"))["config"]
            if stored != config:
                diff = sorted(k for k in set(stored) | set(config) if stored.get(k) != config.get(k))
                raise WbcError(f"{self.dir}: --resume with a different configuration (differs in: "
                               f"{', '.join(diff)}); rerun with the original options or another --out")
        self.records: list[dict[str, object]] = []
        if self.trials_path.exists():
            self.records = read_records(self.trials_path)
            # rewrite without a torn last line so appends start on a fresh line
            self._rewrite()
        else:
            with self.trials_path.open("w", encoding="utf-8", newline="") as f:
                csv.writer(f).writerow(RECORD_FIELDS)
        self.run_path.write_text(json.dumps({"config": config, "environment": provenance()}, indent=2),
                                 encoding="utf-8")
        self._file = self.trials_path.open("a", encoding="utf-8", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=RECORD_FIELDS, extrasaction="ignore")

    def _rewrite(self) -> None:
        tmp = self.trials_path.with_suffix(".tmp")
        with tmp.open("w", encoding="utf-8", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=RECORD_FIELDS, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(self.records)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.trials_path)

    def done(self) -> set[tuple[str, str, int, int]]:
        """Keys (controller, band, seed, trial) already finished."""
        return {(str(r["controller"]), str(r["band"]), int(r["seed"]), int(r["trial"])) for r in self.records}

    def append(self, record: dict[str, object]) -> None:
        """Store one finished trial durably."""
        self._writer.writerow(record)
        self._file.flush()
        os.fsync(self._file.fileno())
        self.records.append(_parse({k: str(record[k]) for k in RECORD_FIELDS}))

    def close(self) -> None:
        """Close the trials file."""
        self._file.close()
