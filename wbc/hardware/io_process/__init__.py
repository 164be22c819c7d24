"""The I/O process: a hardware robot's devices (the legs' link, the arm's bus) in a child process of their own.

`ProcessRobot` (`process_robot.py`) is the robot the controller's process drives; `serve_io_process` (`serve.py`)
is the child's server, which builds and connects the robot and serves it; states and commands cross in shared
memory (`blocks.py`), and requests, replies and failures on a control channel of JSON lines (`channel.py`).
"""

from wbc.hardware.io_process.blocks import IoBlocks
from wbc.hardware.io_process.channel import ChannelClosed, LineChannel, error_report, rebuild_error
from wbc.hardware.io_process.process_robot import ProcessLinkStats, ProcessRobot, build_process_robot
from wbc.hardware.io_process.serve import serve_io_process

__all__ = ["ChannelClosed", "IoBlocks", "LineChannel", "ProcessLinkStats", "ProcessRobot", "build_process_robot",
           "error_report", "rebuild_error", "serve_io_process"]
