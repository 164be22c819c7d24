"""A researcher's own scenario files: what the loader, the exporter and the messages tell them.

Each test stands for a file written by hand (a copy of a shipped scenario with a value changed, a typo in a header,
an inline array of bands, a file too large) and checks that what `wbc` says of it is exact.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from wbc.errors import ScenarioError
from wbc.scenario.push import Push
from wbc.scenario.scenario import load_scenario
from wbc.scenario.trial_file import write_trial_scenario

TURN = Path("scenarios/turn.toml").read_text(encoding="utf-8")
PUSH = Path("scenarios/push.toml").read_text(encoding="utf-8")


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


def test_a_band_whose_pushes_are_all_zero_newtons_is_refused_saying_how_to_play_none(tmp_path):
    zero = tmp_path / "zero.toml"
    zero.write_text(PUSH.replace("push_force_n = [300.0, 400.0]", "push_force_n = [0.0, 0.0]"))
    line = zero.read_text().splitlines().index("push_force_n = [0.0, 0.0]") + 1
    said = _error(zero)
    assert said.startswith(f"{zero}:{line}: [[bands]] #2 push_force_n: [0, 0] makes every push of the band 0 N")
    assert "leave out [pushes] and every band's push_force_n" in said and "--no-push" in said
    zero.write_text(PUSH.replace("push_force_n = [300.0, 400.0]", "push_force_n = [0.0, 400.0]"))
    assert load_scenario(zero).bands == ("in", "ood")  # a lower end of 0 N stays a band of pushes


def test_a_trial_the_schema_refuses_is_not_written_and_leaves_the_file_as_it_was(tmp_path):
    trial = load_scenario("scenarios/push.toml").trial("in", 0, 0)
    nothing = Push(force_in_world=np.zeros(3), offset_in_base=np.zeros(3), start=1.0, duration=0.09)
    played = dataclasses.replace(trial, pushes=(nothing, *trial.pushes))
    fresh, kept = tmp_path / "fresh.toml", tmp_path / "kept.toml"
    kept.write_text("# mine\n")
    for path in (fresh, kept):
        with pytest.raises(ScenarioError, match=r"\[\[fixed_pushes\]\] #1 force_n: its magnitude must be in "
                           r"\(0, 2000\] N, got 0 \(the trial's file was not written\)") as caught:
            write_trial_scenario(path, played, name="zero", description="a push of 0 N")
        assert caught.value.path == str(path)
    assert not fresh.exists() and kept.read_text() == "# mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.toml"]  # no temporary file left either
    write_trial_scenario(fresh, trial, name="pushed", description="the trial itself")
    assert load_scenario(fresh).trial("in", 0, 0).pushes[0].start == trial.pushes[0].start


def test_the_hash_covers_values_as_written_and_not_the_layout(tmp_path):
    """What the scenarios guide says the hash covers."""

    def hash_of(text: str) -> str:
        path = tmp_path / "copy.toml"
        path.write_text(text)
        return load_scenario(path).hash

    published = load_scenario("scenarios/push.toml").hash
    terrain = '[terrain]\nkind = "fractal"\namplitude_m = 0.05\n'
    assert terrain in PUSH
    same = (PUSH.replace("ramp_s = 0.5", "# a comment\nramp_s   =   0.5  # another"),
            PUSH.replace(terrain, "[terrain]\namplitude_m = 0.05\nkind = 'fractal'\n"),  # key order, quoting
            'terrain = {kind = "fractal", amplitude_m = 0.05}\n' + PUSH.replace(terrain, ""))  # inline, first
    assert {hash_of(text) for text in same} == {published}
    other = (PUSH.replace("duration_s = 20.0", "duration_s = 20"),  # an integer, not a float
             PUSH.replace("vx = 0.0\n", "", 1))  # a default left out
    hashes = [hash_of(text) for text in other]
    assert published not in hashes and len(set(hashes)) == 2
