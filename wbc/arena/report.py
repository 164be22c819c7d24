"""Arena report: a JSON summary of the records, the paper-style results table, and a Markdown report with plots.

The input is one `wbc.arena.record.TrialRecord` per (controller, trial). This module turns them into:

- `summarize`: per controller and band, mean +- std across seeds of each metric (`wbc.arena.stats.mean_std_over_seeds`),
  and for every ordered pair of controllers the paired difference B - A with a 95 % bootstrap interval
  (`wbc.arena.stats.paired_difference`). The result is JSON-serialisable: NaN becomes ``None``.
- `format_table`: that summary as plain text, one block per band, in the shape of the paper's results table.
- `write_report`: ``report.md`` plus the PNG plots (drawn by `wbc.arena.plots`) in an output folder.

Everything is deterministic: the same records, in any order, give byte-identical summaries and tables (records are
put `in_canonical_order` before any statistic).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from wbc.arena.plots import PLOTS, write_plots
from wbc.arena.record import TrialRecord
from wbc.arena.stats import in_canonical_order, mean_std_over_seeds, paired_difference
from wbc.errors import RecordError

__all__ = [
    "METRICS",
    "METRIC_KEYS",
    "EXTRA_METRICS",
    "LABELS",
    "summarize",
    "format_table",
    "md_table",
    "write_report",
]

METRICS = ("success_rate", "ttf", "vlin_err", "vang_err")
"""The headline metrics: reported per band and compared pairwise between controllers."""

METRIC_KEYS: Mapping[str, str] = {
    "success_rate": "success",
    "ttf": "ttf",
    "vlin_err": "vlin_err",
    "vang_err": "vang_err",
}
"""Summary metric name -> the record field it is computed from."""

EXTRA_METRICS = ("max_roll_deg", "energy_j", "arm_travel_rad")
"""Secondary metrics reported per band (named as their record fields), not compared pairwise."""

LABELS: Mapping[str, str] = {
    "success_rate": "Success %",
    "ttf": "TTF",
    "vlin_err": "V_lin err [m/s]",
    "vang_err": "V_ang err [rad/s]",
    "max_roll_deg": "Max roll [deg]",
    "energy_j": "Energy [J]",
    "arm_travel_rad": "Arm travel [rad]",
}
"""Summary metric name -> its label (with the unit) in tables and on plot axes."""

_DECIMALS = {"success_rate": 2, "ttf": 3, "vlin_err": 3, "vang_err": 3, "max_roll_deg": 2, "energy_j": 1,
             "arm_travel_rad": 3}
_SCALE = {"success_rate": 100.0}  # success is stored as a fraction, shown in percent (paired: percentage points)


def _json_float(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _records_by_cell(
    records: Iterable[TrialRecord], controllers: Sequence[str], bands: Sequence[str]
) -> dict[str, dict[str, list[TrialRecord]]]:
    """Controller -> band -> its records; records of other controllers or bands are dropped."""
    cells: dict[str, dict[str, list[TrialRecord]]] = {c: {b: [] for b in bands} for c in controllers}
    for record in records:
        if record.controller in cells and record.band in cells[record.controller]:
            cells[record.controller][record.band].append(record)
    return cells


def summarize(
    records: Iterable[TrialRecord],
    *,
    scenario_name: str,
    scenario_hash: str,
    controllers: Sequence[str],
    bands: Sequence[str],
) -> dict[str, Any]:
    """Summarise arena records per controller and band, and compare controllers pairwise.

    For each controller and band: the number of trials, and mean / std across seeds (`mean_std_over_seeds`) of
    `METRICS` (success_rate from the ``success`` field, as a fraction in [0, 1]) and of `EXTRA_METRICS`. For every
    ordered pair (a, b) with a listed before b in `controllers`, every band and every metric in `METRICS`: the
    paired difference b - a and its 95 % bootstrap interval (`paired_difference`, seed 0).

    Records of controllers or bands not listed are ignored. A listed controller or band without records gets
    ``trials: 0`` and ``None`` statistics. The records are put `in_canonical_order` first, so the summary does not
    depend on the order they come in (the order trials finished).

    Args:
        records: arena records, in any order.
        scenario_name: the scenario's name.
        scenario_hash: the scenario file's content hash; every record's ``scenario_hash``, where set, must match.
        controllers: controller names, in the order of the table (the order also fixes which side of each pair is A).
        bands: band names, in the order of the table.

    Returns:
        A JSON-serialisable dict::

            {"scenario": {"name", "hash"},
             "controllers": {NAME: {"bands": {BAND: {"trials": int, METRIC: {"mean", "std"}, ...}}}},
             "paired": [{"a", "b", "band", "metric", "diff", "ci95": [lo, hi]}, ...]}

        with ``None`` wherever a statistic is undefined.

    Raises:
        RecordError: a record repeats a trial, or comes from another version of the scenario.
    """
    records = list(records)
    for record in records:
        if record.scenario_hash and record.scenario_hash != scenario_hash:
            raise RecordError(
                f"a record of controller {record.controller!r} was produced by scenario hash "
                f"{record.scenario_hash!r}, not {scenario_hash!r}; summarise the records of one scenario version at "
                "a time"
            )
    cells = _records_by_cell(in_canonical_order(records, controllers, bands), controllers, bands)
    per_controller: dict[str, Any] = {}
    for controller in controllers:
        per_band: dict[str, Any] = {}
        for band in bands:
            cell = cells[controller][band]
            entry: dict[str, Any] = {"trials": len(cell)}
            for metric in (*METRICS, *EXTRA_METRICS):
                stats = mean_std_over_seeds(cell, METRIC_KEYS.get(metric, metric))
                entry[metric] = {"mean": _json_float(stats["mean"]), "std": _json_float(stats["std"])}
            per_band[band] = entry
        per_controller[controller] = {"bands": per_band}
    paired = []
    for a, b in itertools.combinations(controllers, 2):
        for band in bands:
            for metric in METRICS:
                result = paired_difference(cells[a][band], cells[b][band], METRIC_KEYS[metric])
                paired.append(
                    {
                        "a": a,
                        "b": b,
                        "band": band,
                        "metric": metric,
                        "diff": _json_float(result["diff"]),
                        "ci95": [_json_float(x) for x in result["ci95"]],
                    }
                )
    return {
        "scenario": {"name": scenario_name, "hash": scenario_hash},
        "controllers": per_controller,
        "paired": paired,
    }


def _bands_of(summary: Mapping[str, Any]) -> list[str]:
    bands: list[str] = []
    for entry in summary["controllers"].values():
        for band in entry["bands"]:
            if band not in bands:
                bands.append(band)
    return bands


def _number(value: float | None, metric: str) -> str:
    if value is None:
        return "n/a"
    return f"{value * _SCALE.get(metric, 1.0):.{_DECIMALS[metric]}f}"


def _mean_std(stat: Mapping[str, float | None], metric: str) -> str:
    if stat["mean"] is None:
        return "n/a"
    return f"{_number(stat['mean'], metric)} ± {_number(stat['std'], metric)}"


def _signed(value: float | None, metric: str) -> str:
    if value is None:
        return "n/a"
    return f"{value * _SCALE.get(metric, 1.0):+.{_DECIMALS[metric]}f}"


def _ci(ci95: Sequence[float | None], metric: str) -> str:
    if ci95[0] is None or ci95[1] is None:
        return "n/a"
    return f"[{_signed(ci95[0], metric)}, {_signed(ci95[1], metric)}]"


def _result_rows(summary: Mapping[str, Any], band: str, metrics: Sequence[str]) -> list[list[str]]:
    rows = []
    for controller, entry in summary["controllers"].items():
        cell = entry["bands"].get(band)
        if cell is None:
            rows.append([controller, "0", *("n/a" for _ in metrics)])
        else:
            rows.append([controller, str(cell["trials"]), *(_mean_std(cell[m], m) for m in metrics)])
    return rows


def _paired_rows(summary: Mapping[str, Any]) -> list[list[str]]:
    return [
        [p["band"], p["a"], p["b"], LABELS[p["metric"]], _signed(p["diff"], p["metric"]), _ci(p["ci95"], p["metric"])]
        for p in summary["paired"]
    ]


def _aligned(header: Sequence[str], rows: Sequence[Sequence[str]], indent: str = "  ") -> list[str]:
    widths = [max(len(row[i]) for row in (header, *rows)) for i in range(len(header))]
    lines = [indent + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    lines.append(indent + "  ".join("-" * w for w in widths))
    lines += [indent + "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    return lines


def format_table(summary: Mapping[str, Any]) -> str:
    """Render a summary (from `summarize`) as plain text in the shape of the paper's results table.

    One block per band, one row per controller, columns Trials, Success %, TTF, V_lin err, V_ang err as
    "mean ± std" across seeds (success in percent with 2 decimals, e.g. ``95.02 ± 0.62``; the others with 3). Then a
    block "paired differences (B - A, 95% CI)" with one line per pair, band and metric; success differences are in
    percentage points. Undefined statistics show as ``n/a``.

    Args:
        summary: the output of `summarize` (or the same read back from JSON).

    Returns:
        The table, lines separated by newlines, ending with a newline.
    """
    scenario = summary["scenario"]
    lines = [f"scenario {scenario['name']} ({scenario['hash']})", ""]
    header = ["controller", "trials", *(LABELS[m] for m in METRICS)]
    for band in _bands_of(summary):
        lines.append(f"band {band}")
        lines += _aligned(header, _result_rows(summary, band, METRICS))
        lines.append("")
    lines.append("paired differences (B - A, 95% CI)")
    if summary["paired"]:
        lines += _aligned(["band", "A", "B", "metric", "B - A", "95% CI"], _paired_rows(summary))
    else:
        lines.append("  (fewer than two controllers)")
    return "\n".join(lines) + "\n"


def _md_cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """A Markdown table, one line per row, cells escaped (``|`` and newlines)."""
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return lines


def _md_meta(meta: Mapping[str, Any]) -> list[str]:
    lines = []
    for key, value in meta.items():
        if isinstance(value, Mapping):
            lines.append(f"- **{key}**:")
            lines += [f"  - {sub}: `{_md_cell(v)}`" for sub, v in value.items()]
        elif isinstance(value, list | tuple):
            lines.append(f"- **{key}**: {', '.join(_md_cell(v) for v in value)}")
        else:
            lines.append(f"- **{key}**: {_md_cell(value)}")
    return lines


def write_report(
    out_dir: str | Path, summary: Mapping[str, Any], records: Iterable[TrialRecord], meta: Mapping[str, Any],
    sections: Sequence[tuple[str, Sequence[str]]] = (),
) -> list[Path]:
    """Write ``report.md`` and its PNG plots (`wbc.arena.plots.write_plots`) into `out_dir` (created if missing).

    ``report.md`` holds the title, the scenario name and hash, `meta` as a list (nested mappings as sub-lists), the
    extra `sections`, one Markdown results table per band, the paired-differences table and links to the plots.

    Args:
        out_dir: output folder.
        summary: the output of `summarize` for `records`.
        records: the arena records summarised (used for the per-trial plots), in any order; those of controllers or
            bands not in the summary are ignored.
        meta: run information to list (controllers, seeds, trials, executor, package versions, git revision ...).
        sections: more (title, Markdown lines) sections, placed after the run information (a hardware trial's
            timing, safety events and operator actions).

    Returns:
        The paths written: ``report.md`` first, then the plots.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    controllers = list(summary["controllers"])
    bands = _bands_of(summary)
    plots = write_plots(out, summary, in_canonical_order(records, controllers, bands), controllers=controllers,
                        bands=bands, labels=LABELS)

    scenario = summary["scenario"]
    lines = [f"# Arena report: {scenario['name']}", "", f"Scenario `{scenario['name']}`, hash `{scenario['hash']}`."]
    lines += ["", "## Run", ""]
    lines += _md_meta(meta) if meta else ["(no run information given)"]
    for title, body in sections:
        lines += ["", f"## {title}", "", *body]
    lines += ["", "## Results", "", "Mean ± std across seeds (each seed's trials averaged first); success in %.", ""]
    metrics = (*METRICS, *EXTRA_METRICS)
    for band in bands:
        lines += [f"### Band `{band}`", ""]
        header = ["Controller", "Trials", *(LABELS[m] for m in metrics)]
        lines += md_table(header, _result_rows(summary, band, metrics))
        lines.append("")
    lines += ["## Paired differences (B - A, 95% CI)", ""]
    lines += [
        "Same trials for both controllers; percentile bootstrap over trials. Positive: B larger (better for success "
        "and TTF, worse for tracking errors). Success in percentage points.",
        "",
    ]
    if summary["paired"]:
        lines += md_table(["Band", "A", "B", "Metric", "B - A", "95% CI"], _paired_rows(summary))
    else:
        lines.append("(fewer than two controllers)")
    lines += ["", "## Plots", ""]
    written = {p.name for p in plots}
    for name, title in PLOTS:
        if name in written:
            lines += [f"- [{title}]({name})", "", f"  ![{title}]({name})", ""]
        else:
            lines += [f"- {title}: not drawn (no trial had a push)", ""]
    report = out / "report.md"
    report.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    return [report, *plots]
