"""The browser viewer: meshcat scenes of trials, live or replayed, and self-contained HTML recordings."""

from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import Pose, VizFrame
from wbc.viz.record import Recording
from wbc.viz.server import MeshcatServer, ServerConfig

__all__ = ["MeshcatServer", "Pose", "Recording", "SceneContent", "ServerConfig", "ViewerError", "VizFrame"]
