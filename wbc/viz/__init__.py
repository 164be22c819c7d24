"""The browser viewer: meshcat scenes of trials, live or replayed, and self-contained HTML recordings."""

from wbc.viz.ab import CapturedRun, FrameCapture, ab_recording, capture_trial, first_divergence
from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import Pose, VizFrame
from wbc.viz.live import LiveObserver, LiveViewer
from wbc.viz.live_page import LivePage, PushRequest, SteeredCommand
from wbc.viz.page import live_page_html, read_page_data, save_trial_page, trial_page
from wbc.viz.player import Controls, KeyboardControls, Player, PlayerConfig
from wbc.viz.recording import Recording
from wbc.viz.replay import StoredEpisode, load_stored_episode
from wbc.viz.server import MeshcatServer, ServerConfig
from wbc.viz.signals import PLOTS, Mark, TrialSignals
from wbc.viz.trial_export import ExportedScenario, export_trial, exported_name
from wbc.viz.view import (
    ABResult,
    RecordingTime,
    ViewConfig,
    ViewResult,
    replay_ab,
    replay_episode,
    view_ab,
    view_trial,
)

__all__ = [
    "PLOTS", "ABResult", "CapturedRun", "Controls", "ExportedScenario", "FrameCapture", "KeyboardControls",
    "LiveObserver", "LivePage", "LiveViewer", "Mark", "MeshcatServer", "Player", "PlayerConfig", "Pose", "PushRequest",
    "Recording", "RecordingTime", "SceneContent", "ServerConfig", "SteeredCommand", "StoredEpisode", "TrialSignals",
    "ViewConfig", "ViewResult", "ViewerError", "VizFrame", "ab_recording", "capture_trial", "export_trial",
    "exported_name", "first_divergence", "live_page_html", "load_stored_episode", "read_page_data", "replay_ab",
    "replay_episode", "save_trial_page", "trial_page", "view_ab", "view_trial",
]
