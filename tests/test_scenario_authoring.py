"""A researcher's own scenario files: what the loader, the exporter and the messages tell them.

Each test stands for a file written by hand (a copy of a shipped scenario with a value changed, a typo in a header,
an inline array of bands, a file too large) and checks that what `wbc` says of it is exact.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from wbc.errors import ScenarioError
from wbc.scenario.scenario import load_scenario

TURN = Path("scenarios/turn.toml").read_text(encoding="utf-8")


def test_a_file_over_the_size_limit_gives_its_exact_size(tmp_path):
    big = tmp_path / "big.toml"
    big.write_bytes(TURN.encode() + b"#" * (1_069_152 - len(TURN.encode()) - 1) + b"\n")
    assert big.stat().st_size == 1_069_152
    with pytest.raises(ScenarioError, match=r"1,069,152 bytes, more than the 1 MiB a toml file may have"):
        load_scenario(big)


def _error(path: Path) -> str:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    return str(caught.value)


def test_a_misspelt_array_of_tables_is_named_at_its_header_line(tmp_path):
    typo = tmp_path / "typo.toml"
    typo.write_text(TURN.replace("[[commands.options]]", "[[command.options]]", 1))
    line = typo.read_text().splitlines().index("[[command.options]]  # slow turn") + 1
    assert _error(typo).startswith(f"{typo}:{line}: [command]: unknown table")


def test_a_bad_value_in_an_inline_array_of_tables_is_named_at_the_arrays_line(tmp_path):
    bands = TURN[TURN.index("[[bands]]"):]
    inline = tmp_path / "inline.toml"
    # an inline array belongs to the table above it: written first, it is the top level's
    inline.write_text('bands = [\n  {name = "slow", vx = 1.0},\n  {name = "fast", vx = 9},\n]\n'
                      + TURN.replace(bands, ""))
    line = inline.read_text().splitlines().index("bands = [") + 1
    assert _error(inline).startswith(f"{inline}:{line}: [[bands]] #2 vx: must be in [-3, 3], got 9")
