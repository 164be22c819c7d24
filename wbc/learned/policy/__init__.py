"""Torch-free inference of exported policies: the policy file formats, observations, numpy networks, the controller."""

from wbc.learned.policy.composite_policy import CompositePolicyFile, PolicyPart, load_composite, save_composite
from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.numpy_composite import NumpyComposite
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.obs_history import ObsHistory
from wbc.learned.policy.observations import ObsLayout, compatible_observation, policy_observation
from wbc.learned.policy.policy_file import PolicyFile, PolicyFileError, load_policy, save_policy
from wbc.learned.policy.shipped import WEIGHTS_DIR, shipped_weights

__all__ = ["WEIGHTS_DIR", "CompositePolicyFile", "LearnedController", "NumpyComposite", "NumpyPolicy", "ObsHistory",
           "ObsLayout", "PolicyFile", "PolicyFileError", "PolicyPart", "compatible_observation", "load_composite",
           "load_policy", "policy_observation", "save_composite", "save_policy", "shipped_weights"]
