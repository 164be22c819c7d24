"""The browser viewer: meshcat scenes of trials, live or replayed, and self-contained HTML recordings."""

from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import Pose, VizFrame
from wbc.viz.live import LiveObserver, LiveViewer
from wbc.viz.player import Controls, KeyboardControls, Player, PlayerConfig
from wbc.viz.record import Recording
from wbc.viz.replay import StoredEpisode, load_stored_episode
from wbc.viz.server import MeshcatServer, ServerConfig
from wbc.viz.view import ViewConfig, ViewResult, replay_episode, view_trial

__all__ = [
    "Controls", "KeyboardControls", "LiveObserver", "LiveViewer", "MeshcatServer", "Player", "PlayerConfig", "Pose",
    "Recording", "SceneContent", "ServerConfig", "StoredEpisode", "ViewConfig", "ViewResult", "ViewerError",
    "VizFrame", "load_stored_episode", "replay_episode", "view_trial",
]
