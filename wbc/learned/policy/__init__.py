"""Torch-free inference of exported policies: the policy file formats, observations, numpy networks, the controller.

Also the replay file (`replay_file`: a policy's observation / action pairs with the robot states they came from).
Its recorder, `wbc.learned.policy.replay_recorder.record_replay`, runs the simulator and is imported by name.
"""

from wbc.learned.policy.composite_policy import CompositePolicyFile, PolicyPart, load_composite, save_composite
from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.numpy_composite import NumpyComposite
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.obs_history import ObsHistory
from wbc.learned.policy.observations import ObsLayout, compatible_observation, policy_observation
from wbc.learned.policy.policy_file import PolicyFile, PolicyFileError, load_policy, save_policy
from wbc.learned.policy.replay_file import Replay, ReplayFileError, load_replay, replay_path_for, save_replay
from wbc.learned.policy.shipped import WEIGHTS_DIR, shipped_weights

__all__ = ["WEIGHTS_DIR", "CompositePolicyFile", "LearnedController", "NumpyComposite", "NumpyPolicy", "ObsHistory",
           "ObsLayout", "PolicyFile", "PolicyFileError", "PolicyPart", "Replay", "ReplayFileError",
           "compatible_observation", "load_composite", "load_policy", "load_replay", "policy_observation",
           "replay_path_for", "save_composite", "save_policy", "save_replay", "shipped_weights"]
