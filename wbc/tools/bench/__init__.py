"""Speed figures (``wbc bench ...``): measured, printed, never asserted by tests; one module per bench.

``sim`` (physics), ``mpc`` (the MPC controller in closed loop), ``sweep`` (a whole arena sweep), ``train`` (the
training env), each beside the references its targets are stated against (``references``); ``hw`` (the Unitree
low-level link over loopback, against an emulator in another process); ``latency`` (the wire's loop latency, the
simulated delay that plays it, and how much actuation delay each controller survives); ``arm`` (the arm's Dynamixel
bus loop, its rate and step response, against the emulated robot in another process); ``act`` (each controller's
``act`` in CPU per call and per simulated second, on the same trial).
"""

from wbc.tools.bench.act import ActBenchResult, ActCost, bench_act
from wbc.tools.bench.arm import ArmBenchResult, ArmRateRow, ArmReactionRow, ArmStepRow, EmulatorTimingRow, bench_arm
from wbc.tools.bench.hw import EmulatorCounts, HwBenchResult, SafetyBenchResult, bench_hw
from wbc.tools.bench.latency import DelayMargin, LatencyBenchResult, WireLatency, bench_latency
from wbc.tools.bench.mpc import MpcBenchResult, MpcReference, MpcRound, MpcTickFigures, bench_mpc
from wbc.tools.bench.references import (
    MPC_REFERENCE_TARGETS,
    REFERENCE_TARGETS,
    TRAIN_TARGET,
    machine_description,
    reference_a1,
    reference_placo_tick_us,
)
from wbc.tools.bench.sim import SimBenchResult, SimReference, bench_sim
from wbc.tools.bench.sweep import SweepBenchResult, SweepExecutorRow, bench_sweep
from wbc.tools.bench.train import TrainBenchResult, TrainReference, bench_train

__all__ = ["MPC_REFERENCE_TARGETS", "REFERENCE_TARGETS", "TRAIN_TARGET", "ActBenchResult", "ActCost", "ArmBenchResult",
           "ArmRateRow",
           "ArmReactionRow", "ArmStepRow", "DelayMargin", "EmulatorCounts", "EmulatorTimingRow", "HwBenchResult",
           "LatencyBenchResult", "MpcBenchResult", "MpcReference", "MpcRound", "MpcTickFigures", "SafetyBenchResult",
           "SimBenchResult", "SimReference", "SweepBenchResult", "SweepExecutorRow", "TrainBenchResult",
           "TrainReference", "WireLatency", "bench_act", "bench_arm", "bench_hw", "bench_latency", "bench_mpc",
           "bench_sim", "bench_sweep", "bench_train", "machine_description", "reference_a1", "reference_placo_tick_us"]
