"""Export a policy file (single or composite) to ONNX, with the I/O file an ``onnx:PATH`` controller reads.

The ONNX graph takes the raw policy observation of the last F ticks, oldest first, flattened (F = the longest RMA
history among the parts, 1 without one), and returns the action of every joint in the house order. Inside the graph,
as `LearnedController` computes it: each part normalises its own view of the observation
(`wbc.learned.policy.composite_policy.PolicyPart.observation_index`), estimates its extrinsics with its adaptation
module from the last H of its normalised observations when it has one, and runs its MLP; the parts' outputs are put
in joint order. Everything else the controller does around the network (observation terms and scales, the action
clip and scale, the PD gains, the rate) is written to the I/O file (`wbc.control.onnx_io` reads it), in the
observation terms Isaac Lab names, with the model file's sha256 (``[onnx] sha256``), which ``onnx:PATH`` verifies
before any trial: the I/O file sits beside the model and travels with it, so the pair needs no third file.

The round trip is the test of both sides: the shipped pi3 exported here and run as ``onnx:PATH`` gives the numpy
controller's actions within 1e-5. This is also what a policy trained elsewhere looks like to the arena: an ONNX file
and its I/O file.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from wbc.learned.policy.composite_policy import CompositePolicyFile, PolicyPart, load_composite
from wbc.learned.policy.observations import ObsLayout
from wbc.learned.policy.policy_file import weights_sha256
from wbc.learned.policy.replay_file import replay_path_for
from wbc.learned.policy.replay_recorder import record_replay
from wbc.learned.train.torch_policy import sequential
from wbc.optional import require
from wbc.robots.registry import get_robot

torch = require("torch")

__all__ = ["OnnxGraph", "export_onnx", "io_text"]


class _Part(torch.nn.Module):
    """One network of a policy file, on the stacked observation frames."""

    def __init__(self, part: PolicyPart, num_joints: int) -> None:
        super().__init__()
        meta, a = part.policy.meta, part.policy.arrays
        eps = float(meta["normalizer_eps"])
        self.register_buffer("index", torch.as_tensor(part.observation_index(num_joints), dtype=torch.long))
        self.register_buffer("mean", torch.as_tensor(a["obs_mean"], dtype=torch.float32))
        self.register_buffer("div", torch.as_tensor(a["obs_std"], dtype=torch.float32) + eps)
        self.mlp = sequential(part.policy.layers("policy"), meta["activation"])
        adapt = meta.get("adaptation")
        self.history = int(adapt["history"]) if adapt is not None else 0
        if self.history:
            self.adaptation = sequential(part.policy.layers("adaptation"), meta["activation"])

    def forward(self, frames):
        """Actions of this part's joints from (B, F, D) raw observation frames, oldest first."""
        x = (frames[:, -1].index_select(-1, self.index) - self.mean) / self.div
        if self.history:
            window = (frames[:, -self.history:].index_select(-1, self.index) - self.mean) / self.div
            z = self.adaptation(window.reshape(window.shape[0], -1))
            x = torch.cat([x, z], dim=-1)
        return self.mlp(x)


class OnnxGraph(torch.nn.Module):
    """A policy file as one torch module: stacked raw observations in, every joint's action out.

    Args:
        policy: the loaded file (a single policy is a composite of one part).
        num_joints: the robot's actuated joints.

    Attributes:
        frames: observation frames the input holds (F).
        frame_size: entries of one frame (D).
    """

    def __init__(self, policy: CompositePolicyFile, num_joints: int) -> None:
        super().__init__()
        self.parts = torch.nn.ModuleList(_Part(p, num_joints) for p in policy.parts)
        self.frames = max([1, *(p.history for p in self.parts)])
        self.frame_size = ObsLayout(num_joints).size
        joints = np.concatenate([np.asarray(p.joints) for p in policy.parts])
        self.register_buffer("order", torch.as_tensor(np.argsort(joints), dtype=torch.long))
        self.requires_grad_(False)
        self.eval()

    def forward(self, obs):
        """(B, F * D) raw observations, oldest frame first -> (B, num_joints) actions in the house joint order."""
        frames = obs.reshape(obs.shape[0], self.frames, self.frame_size)
        return torch.cat([p(frames) for p in self.parts], dim=-1).index_select(-1, self.order)


def _toml_list(values) -> str:
    return "[" + ", ".join(repr(float(v)) if not isinstance(v, str) else f'"{v}"' for v in values) + "]"


def io_text(policy: CompositePolicyFile, frames: int, *, source: str, sha256: str | None = None) -> str:
    """The I/O file (``wbc.control.onnx_io`` schema) of a policy file exported with `frames` observation frames.

    Args:
        policy: the policy file exported.
        frames: observation frames the model's input holds.
        source: the policy file's path, named in the comment and the summary.
        sha256: the model file's sha256 (hex), written as ``[onnx] sha256``; None: none written.
    """
    meta = policy.meta
    desc = get_robot(meta["robot"], meta["arm_mode"])
    scales = meta["obs_scales"]
    terms = [("base_ang_vel", scales["ang_vel"]), ("projected_gravity", None),
             ("velocity_commands", scales["command"]), ("joint_pos_rel", scales["dof_pos"]),
             ("joint_vel", scales["dof_vel"]), ("last_action", None)]
    lines = [
        f"# What {Path(source).name}'s ONNX export eats and outputs (read by wbc's onnx:PATH controller).",
        "",
        "[policy]",
        f'robot = "{meta["robot"]}"',
        f'arm_mode = "{meta["arm_mode"]}"',
        f"rate_hz = {1.0 / float(meta['policy_dt'])!r}",
        f"joints = {_toml_list(desc.joint_names)}",
        f"default_q = {_toml_list(meta['default_q'])}",
        f'summary = "{meta["task"]} task, stage {meta["stage"]}, exported from {Path(source).name}"',
        "",
        "[onnx]",
        'input = "obs"',
        'output = "actions"',
        *([f'sha256 = "{sha256}"'] if sha256 is not None else []),
        "",
        "[observation]",
        f"history = {frames}",
        'history_order = "frames"',
        'history_fill = "first"',
    ]
    for name, scale in terms:
        lines += ["", "[[observation.terms]]", f'name = "{name}"']
        if scale is not None:
            lines.append(f"scale = {_toml_list(scale) if isinstance(scale, list | tuple) else repr(float(scale))}")
    lines += [
        "",
        "[action]",
        'kind = "joint_position"',
        f"scale = {float(meta['action_scale'])!r}",
        f"clip = {float(meta['clip_actions'])!r}",
        "",
        "[pd]",
        f"kp = {_toml_list(meta['kp'])}",
        f"kd = {_toml_list(meta['kd'])}",
    ]
    return "\n".join(lines) + "\n"


def export_onnx(policy: str | Path, out: str | Path, *, replay: bool = True) -> tuple[Path, Path]:
    """Write ``<out>.onnx`` and its I/O file ``<out>.toml`` for a policy file (single or composite).

    The weights are inside the model (no external data file), and the I/O file records the model's sha256. With
    `replay`, ``<out>.replay.npz`` records a short
    rollout of the policy (`wbc.learned.policy.replay_recorder.record_replay`), against which
    ``wbc check-controller onnx:<out>.onnx --replay <out>.replay.npz`` checks the export and its I/O file.

    Args:
        policy: the policy file (``.npz``, ``.json`` or their stem).
        out: the output path; its suffix is replaced.
        replay: also write the replay file.

    Returns:
        The model's path and the I/O file's.

    Raises:
        PolicyFileError: the policy file is missing or malformed.
    """
    composite = load_composite(policy)
    desc = get_robot(composite.meta["robot"], composite.meta["arm_mode"])
    graph = OnnxGraph(composite, desc.num_joints)
    stem = Path(out).with_suffix("")
    stem.parent.mkdir(parents=True, exist_ok=True)
    model, io = stem.with_suffix(".onnx"), stem.with_suffix(".toml")
    example = torch.zeros(1, graph.frames * graph.frame_size)
    with warnings.catch_warnings():
        # the TorchScript exporter (deprecated, hence the silenced warnings): for a static MLP it writes the graph
        # the torch.export one does at a twentieth of the time (1 s against 20-50 s on 2 cores), and the pinned
        # torch still has it
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(graph, (example,), str(model), input_names=["obs"], output_names=["actions"], dynamo=False)
    io.write_text(io_text(composite, graph.frames, source=str(policy), sha256=weights_sha256(model)),
                  encoding="utf-8")
    if replay:
        record_replay(policy, replay_path_for(model))
    return model, io
