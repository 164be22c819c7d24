"""``wbc scenario check FILE``: a scenario's identity, bands, trial count and publication, without playing a trial."""

import json
from pathlib import Path

from wbc.cli.main import main
from wbc.scenario import load_scenario
from wbc.scenario.scenario_check import TRIAL_COUNT, check_scenario

ROOT = Path(__file__).resolve().parent.parent
PUSH = ROOT / "scenarios" / "push.toml"


def test_a_published_scenario_is_described_and_its_lock_named(capsys):
    assert main(["scenario", "check", str(PUSH)]) == 0
    out = capsys.readouterr().out
    scenario = load_scenario(PUSH)
    assert f"scenario push version {scenario.version}" in out and scenario.hash in out
    assert "a1-wx200" in out and "push_force_n 200-300" in out and TRIAL_COUNT in out
    assert f"published by {ROOT / 'scenarios' / 'published.toml'}" in out


def test_an_unpublished_copy_gets_the_lines_that_publish_it_and_status_1(tmp_path, capsys):
    mine = tmp_path / "mine.toml"
    mine.write_text(PUSH.read_text().replace('name = "push"', 'name = "mine"'))
    assert main(["scenario", "check", str(mine), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    digest = load_scenario(mine).hash
    assert data["name"] == "mine" and data["hash"] == digest and not data["published"]
    assert f'[mine]\n    "{data["version"]}" = "{digest}"' in data["problem"]
    (tmp_path / "published.toml").write_text(f'[mine]\n"{data["version"]}" = "{digest}"\n')
    result = check_scenario(mine)
    assert result.published and result.problem is None and [b for b, _ in result.bands] == ["in", "ood"]
