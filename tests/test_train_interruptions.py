"""An interrupted `wbc train`: what its run directory keeps, and that --resume continues from it."""

from __future__ import annotations

import errno
import shutil
from pathlib import Path

import numpy as np
import pytest

from wbc.learned.env.env_config import DomainRandomisation

torch = pytest.importorskip("torch")
pytest.importorskip("rsl_rl")

SCENARIO = str(Path(__file__).resolve().parent.parent / "scenarios" / "push.toml")


def _tiny(root: Path, **kw):
    """A push stage-1 run of 8 environments and tiny networks, a checkpoint every iteration, no adaptation phase."""
    from wbc.learned.train.adaptation_config import AdaptationConfig
    from wbc.learned.train.stages import stage_config

    small = dict(seed=0, num_steps_per_env=6, save_interval=1, actor_hidden_dims=(16,), critic_hidden_dims=(16,),
                 encoder_dims=(8,), extrinsics_dim=4, rma=AdaptationConfig(iterations=0))
    return stage_config("push", 1, run_root=str(root), env_overrides=dict(
        num_envs=8, nthread=1, scenario=SCENARIO, domain=DomainRandomisation(num_variants=2), seed=0),
        **{**small, **kw})


@pytest.fixture(scope="module")
def two_iterations(tmp_path_factory) -> Path:
    """A finished two-iteration run (model_0.pt, model_1.pt): its run root."""
    from wbc.learned.train.train import train

    root = tmp_path_factory.mktemp("runs")
    train(_tiny(root, max_iterations=2))
    return root


def _files(run_dir: Path) -> dict[str, bytes]:
    """The checkpoints, the exported policy and the progress of a run directory, and any temporary file."""
    return {p.name: p.read_bytes() for p in sorted(run_dir.iterdir())
            if p.name.startswith(("model_", "policy.", "progress.")) or p.name.endswith(".tmp")}


def test_a_checkpoint_whose_write_fails_leaves_the_checkpoints_before_it_whole(two_iterations, tmp_path, monkeypatch):
    from wbc.learned.train.preflight import latest_checkpoint
    from wbc.learned.train.train import train

    shutil.copytree(two_iterations, tmp_path / "runs")
    run = tmp_path / "runs" / "push-stage1"
    before = _files(run)
    assert {"model_0.pt", "model_1.pt"} <= set(before)
    save = torch.save

    def torn(obj, f, *args, **kwargs):
        """A megabyte of the checkpoint written, then the disk is full (a kill leaves the same torn file)."""
        save(obj, f, *args, **kwargs)
        with open(f, "r+b") as out:
            out.truncate(min(1 << 20, out.seek(0, 2) // 2))
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", torn)
    with pytest.raises(OSError, match="No space left"):
        train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)
    monkeypatch.setattr(torch, "save", save)
    assert _files(run) == before  # no model_2.pt, whole or torn, nor its temporary file; the export not refreshed
    assert latest_checkpoint(run).name == "model_1.pt"
    result = train(_tiny(tmp_path / "runs", max_iterations=3), resume=True)  # the resume the audit saw refused
    assert result["iterations"] == 3 and latest_checkpoint(run).name == "model_2.pt"
    assert _files(run)["model_1.pt"] == before["model_1.pt"]


def test_a_policy_file_whose_write_fails_leaves_the_pair_before_it_whole(two_iterations, tmp_path, monkeypatch):
    import wbc.output_files
    from wbc.learned.policy.policy_file import PolicyFile, PolicyFileError, load_policy, save_policy

    npz, js = tmp_path / "policy.npz", tmp_path / "policy.json"
    for path in (npz, js):
        shutil.copy(two_iterations / "push-stage1" / path.name, path)
    before = {p: p.read_bytes() for p in (npz, js)}
    old = load_policy(npz)
    new = PolicyFile(meta=old.meta, arrays={k: v + 1.0 for k, v in old.arrays.items()})
    # the JSON's temporary file cannot be written (a directory stands there): neither file changes
    (tmp_path / "policy.json.tmp").mkdir()
    with pytest.raises(OSError):
        save_policy(tmp_path / "policy", new)
    assert {p: p.read_bytes() for p in (npz, js)} == before and not (tmp_path / "policy.npz.tmp").exists()
    (tmp_path / "policy.json.tmp").rmdir()
    # killed between the two renames: the new weights beside the old JSON, a pair refused for its checksum, never one
    # that loads with another pair's metadata
    replace = wbc.output_files.os.replace

    def killed_before_the_json(src, dst):
        if Path(dst) == js:
            raise KeyboardInterrupt
        replace(src, dst)

    monkeypatch.setattr(wbc.output_files.os, "replace", killed_before_the_json)
    with pytest.raises(KeyboardInterrupt):
        save_policy(tmp_path / "policy", new)
    monkeypatch.setattr(wbc.output_files.os, "replace", replace)
    assert js.read_bytes() == before[js] and not list(tmp_path.glob("*.tmp"))
    with pytest.raises(PolicyFileError, match="sha256"):
        load_policy(npz)
    save_policy(tmp_path / "policy", new)  # written again: whole
    np.testing.assert_array_equal(load_policy(npz).arrays["obs_mean"], new.arrays["obs_mean"])
