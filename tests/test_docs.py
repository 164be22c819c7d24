"""The README and the documentation site stay what they promise.

The README is short (at most 250 lines), written for users (no issue numbers), and its tour runs: every command of
the fenced blocks under "A ten-minute tour" is run as written, from a fresh directory that holds the checkout's
scenarios and examples, as a user runs them from the checkout's root. Every page under docs/ is in the site's nav, and
the site builds with `mkdocs build --strict` (broken links and anchors are errors) when MkDocs is installed (the
``docs`` extra).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = ROOT / "docs"
TOUR_HEADING = "## A ten-minute tour"
COMMAND_TIMEOUT_S = 120
ISSUE_NUMBER = re.compile(r"\bissues? [0-9]", re.IGNORECASE)


def _section(text: str, heading: str) -> str:
    """The lines under `heading` up to the next heading of the same level."""
    lines = text.splitlines()
    start = lines.index(heading)
    level = heading.split(" ", 1)[0]
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith(level + " ")), len(lines))
    return "\n".join(lines[start + 1:end])


def _fenced_blocks(text: str, language: str = "bash") -> list[list[str]]:
    """The fenced code blocks of `language` in `text`, each a list of commands (continuations joined, comments out)."""
    blocks = []
    for body in re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL):
        commands, pending = [], ""
        for line in body.splitlines():
            if pending:
                line = pending + " " + line.strip()
                pending = ""
            if line.rstrip().endswith("\\"):
                pending = line.rstrip()[:-1].rstrip()
                continue
            if line.strip() and not line.lstrip().startswith("#"):
                commands.append(line.strip())
        blocks.append(commands)
    return blocks


def _nav_pages(nav: object) -> list[str]:
    """Every page path named in an mkdocs nav (nested lists of strings and one-key dicts)."""
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, list):
        return [page for item in nav for page in _nav_pages(item)]
    if isinstance(nav, dict):
        return [page for value in nav.values() for page in _nav_pages(value)]
    return []


def test_readme_is_short_and_has_no_issue_numbers():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250, f"README.md has {len(text.splitlines())} lines; move detail into docs/"
    found = ISSUE_NUMBER.findall(text)
    assert not found, f"README.md names issue numbers: {found}"


def test_readme_links_resolve():
    text = README.read_text(encoding="utf-8")
    targets = [t for t in re.findall(r"\]\(([^)\s]+)\)", text) if not re.match(r"[a-z]+:", t)]
    assert targets, "the README links into the docs"
    broken = [t for t in targets if not (ROOT / t.split("#", 1)[0]).exists()]
    assert not broken, f"README.md links to files that do not exist: {broken}"


def test_docs_have_no_issue_numbers():
    offenders = [f"{path.relative_to(ROOT)}:{i}" for path in sorted(DOCS.rglob("*.md"))
                 for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                 if ISSUE_NUMBER.search(line)]
    assert not offenders, f"issue numbers in the docs: {offenders}"


def test_every_docs_page_is_in_the_nav():
    yaml = pytest.importorskip("yaml")
    config = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=yaml.BaseLoader)
    in_nav = set(_nav_pages(config["nav"]))
    pages = {str(path.relative_to(DOCS)) for path in DOCS.rglob("*.md")}
    assert pages - in_nav == set(), f"pages missing from mkdocs.yml's nav: {sorted(pages - in_nav)}"
    assert in_nav - pages == set(), f"nav entries without a page: {sorted(in_nav - pages)}"


def test_tour_blocks_are_found():
    blocks = _fenced_blocks(_section(README.read_text(encoding="utf-8"), TOUR_HEADING))
    commands = [command for block in blocks for command in block]
    assert len(blocks) >= 5, "the tour has a block per step: demo, compare, viewer, your controller, hardware"
    for word in ("wbc demo", "wbc compare", "wbc view", "wbc check-controller", "wbc hw emulate", "wbc hw run"):
        assert any(command.startswith(word) for command in commands), f"the tour lost its `{word}` step"


def _run_block(block: list[str], cwd: Path, env: dict[str, str]) -> None:
    """Run a block's commands in order, in `cwd`; one ending in `&` runs in the background until the block ends.

    ``wbc hw run`` plays against the emulator on the real clock, behind the safety layer: on a busy machine the layer
    can trip on a stale state during the stand-up, as the tour says it may, and then plays nothing (exit 2, "nothing
    was played"). That command is run again then, up to three times in all; any other failure fails at once.
    """
    background: list[subprocess.Popen] = []
    try:
        for command in block:
            if command.endswith("&"):
                background.append(subprocess.Popen(["bash", "-c", command[:-1].strip()], cwd=cwd, env=env,
                                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                                   start_new_session=True))
                continue
            for _ in range(3 if command.startswith("wbc hw run") else 1):
                done = subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True, text=True,
                                      timeout=COMMAND_TIMEOUT_S)
                if done.returncode != 2 or "nothing was played" not in done.stderr:
                    break
            assert done.returncode == 0, (f"the README's tour command failed ({done.returncode}): {command}\n"
                                          f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    finally:
        for process in background:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()


def test_tour_commands_run_as_written(tmp_path):
    if shutil.which("wbc", path=str(Path(sys.executable).parent)) is None:
        pytest.skip("the `wbc` command is not installed beside this interpreter")
    for name in ("scenarios", "examples"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = ""
    for block in _fenced_blocks(_section(README.read_text(encoding="utf-8"), TOUR_HEADING)):
        _run_block(block, tmp_path, env)
    assert (tmp_path / "runs" / "tour-demo" / "report.md").is_file()
    assert (tmp_path / "runs" / "tour-trial.html").is_file()
    assert (tmp_path / "runs" / "tour-hw" / "trials.csv").is_file()


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir",
                           str(tmp_path / "site")], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, timeout=300)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout[-4000:]}\n{done.stderr[-4000:]}"


def _shipped_files_section() -> str:
    text = (DOCS / "guides" / "learned.md").read_text()
    return text[text.index("## The shipped files"):text.index("## The turn task on go1-arm")]


def _expand(pattern: str) -> list[str]:
    """A file pattern as the guide writes it: ``a1-wx200-{none,locked}`` and ``go1-arm-*-crouched``."""
    m = re.search(r"\{([^}]*)\}", pattern)
    if m is None:
        return [pattern]
    return [name for part in m.group(1).split(",") for name in _expand(pattern[:m.start()] + part + pattern[m.end():])]


def test_the_learned_guide_says_which_scenario_trained_every_shipped_file():
    """Each shipped weight file is in the guide's table, whose row names its scenario (push v1 or v2, turn file)."""
    section = _shipped_files_section()
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    named: dict[str, str] = {}
    for row in rows:
        files, _, scenario = row.strip("|").split(" | ")[:3]
        for pattern in re.findall(r"`([^`]+)`", files):
            for name in _expand(pattern):
                named[name] = scenario
    shipped = sorted(p.stem for p in (ROOT / "wbc" / "learned" / "weights").glob("*.json"))
    from fnmatch import fnmatch

    for stem in shipped:
        scenarios = [scenario for pattern, scenario in named.items() if fnmatch(stem, pattern)]
        assert scenarios, f"{stem}: not in the guide's table of shipped files"
    # the crouched push set met push v1's pushes, the upright chain push v2's
    assert "version 1" in named["a1-wx200-actuated-crouched"] and "version 2" in named["a1-wx200-actuated"]
    assert "was trained on push version 1" not in (DOCS / "guides" / "learned.md").read_text()


def test_the_learned_guide_quotes_the_bc_weight_the_schedule_gives_at_each_runs_last_iteration():
    from wbc.learned.train.bc_schedule import BCSchedule

    schedule = BCSchedule(hold_iterations=50, anneal_iterations=150)  # the stages' schedule
    text = " ".join((DOCS / "guides" / "learned.md").read_text().split())
    # the crouched pi2 ran 127 iterations (its last, 126), pi3 125 (124); the turn runs 100 (99)
    assert f"{schedule.weight(126):.2f} (pi2, iteration 126)" in text
    assert f"{schedule.weight(124):.2f} (pi3, iteration 124" in text
    assert f"lambda had reached {schedule.weight(99):.2f} at the runs' last iteration, 99" in text
    assert "annealed only to 0.67 (pi2)" not in text


def _flat(text: str) -> str:
    """`text` with its line breaks as spaces: a sentence of the docs, wherever it wraps."""
    return " ".join(text.split())


def test_the_exit_statuses_name_hw_emulate_as_the_exception_to_130() -> None:
    """The commands page said that any command exits 130 when interrupted; ``wbc hw emulate`` stops on Ctrl-C by
    design and exits 0 once it serves."""
    text = _flat((DOCS / "commands.md").read_text(encoding="utf-8"))
    assert ("`wbc hw emulate` is the exception: once it serves, a Ctrl-C, SIGTERM or SIGHUP is how it stops, and it "
            "prints its counts and exits 0") in text


def test_the_results_directory_gives_summary_units_and_trials_csv_line_endings() -> None:
    """summary.json's success is a fraction where the tables print percent, and trials.csv's rows end in CRLF (the csv
    module's default, which the results store keeps): the guide says both."""
    import csv
    import inspect

    from wbc.arena import results

    assert csv.excel.lineterminator == "\r\n"  # the dialect csv.writer takes by default
    assert "lineterminator" not in inspect.getsource(results)
    text = _flat(_section((DOCS / "guides" / "arena.md").read_text(encoding="utf-8"), "## The results directory"))
    assert "`success_rate` and `ttf`, and a paired difference of `success`" in text
    assert "are fractions from 0 to 1, where the tables and the report print success in percent" in text
    assert "`vlin_err` and `vlin_err_common` are m/s, `vang_err` and `vang_err_common` rad/s" in text
    assert "each row ends in CRLF (`\\r\\n`)" in text
