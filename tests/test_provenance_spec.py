"""`ControllerSpec.provenance`: what a run records of each kind of controller (registry, policy file, any spec).

Plug-ins and entry points are covered in test_plugins.py, ONNX models and their external data in
test_onnx_policy.py.
"""

import hashlib
import json
import pickle
import shutil
from importlib import metadata

from wbc.control.registry import arm_variant, get_controller
from wbc.control.spec import ControllerSpec, SourceFile
from wbc.control.stand import StandController
from wbc.learned.policy.shipped import WEIGHTS_DIR


def _sha(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_registry_controllers_record_the_wbc_version_and_the_shipped_weights_they_run():
    stand = get_controller("stand").provenance()
    assert stand == {"name": "stand", "kind": "registry", "arm_mode": "actuated",
                     "wbc_version": metadata.version("wbc"), "files": []}
    learned = get_controller("learned")
    files = learned.provenance()["files"]
    assert [(f["role"], f["path"]) for f in files] == [
        (role, str(WEIGHTS_DIR / f"{robot}-actuated{suffix}")) for robot in learned.robots
        for role, suffix in (("weights", ".npz"), ("policy metadata", ".json"))]
    for f in files:
        assert f["sha256"] == _sha(f["path"])
    # a variant of another arm mode records its own weights
    locked = arm_variant(learned, "locked").provenance()["files"]
    assert {f["path"] for f in locked} == {str(WEIGHTS_DIR / f"{robot}-locked{suffix}")
                                           for robot in learned.robots for suffix in (".npz", ".json")}
    json.dumps(learned.provenance())


def test_a_policy_file_records_both_files_and_a_changed_byte_changes_its_hash(tmp_path):
    for suffix in (".npz", ".json"):
        shutil.copy(WEIGHTS_DIR / f"a1-wx200-none{suffix}", tmp_path / f"pi1{suffix}")
    name = f"policy:{tmp_path / 'pi1'}"
    before = {f["role"]: f for f in get_controller(name).provenance()["files"]}
    assert before["weights"]["path"] == str(tmp_path / "pi1.npz")
    assert before["weights"]["sha256"] == _sha(WEIGHTS_DIR / "a1-wx200-none.npz")
    assert before["policy metadata"]["sha256"] == _sha(WEIGHTS_DIR / "a1-wx200-none.json")
    with open(tmp_path / "pi1.json", "a") as f:
        f.write(" ")  # same JSON, another file
    after = {f["role"]: f["sha256"] for f in get_controller(name).provenance()["files"]}
    assert after["policy metadata"] != before["policy metadata"]["sha256"]
    assert after["weights"] == before["weights"]["sha256"]


def test_files_are_hashed_once_per_spec_and_the_record_survives_pickling(tmp_path):
    weights = tmp_path / "w.bin"
    weights.write_bytes(b"first")
    spec = ControllerSpec("mine", "actuated", StandController, "test", files=(SourceFile(role="weights",
                                                                                         path=str(weights)),))
    first = spec.provenance()
    assert first["files"] == [{"role": "weights", "path": str(weights), "sha256": _sha(weights)}]
    weights.write_bytes(b"second")
    assert spec.provenance() == first  # the spec says what it was resolved with
    assert pickle.loads(pickle.dumps(spec)).provenance() == first  # as a pool or Ray worker receives it
    fresh = ControllerSpec("mine", "actuated", StandController, "test", files=spec.files).provenance()
    assert fresh["files"][0]["sha256"] == _sha(weights) != first["files"][0]["sha256"]
    weights.unlink()
    gone = ControllerSpec("mine", "actuated", StandController, "test", files=spec.files).provenance()["files"][0]
    assert gone["sha256"] is None and "FileNotFoundError" in gone["error"]
