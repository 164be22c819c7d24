"""The procedures the ``wbc`` command runs, on top of the arena.

Speed benches, the tail analysis, the arm-momentum and posture studies, the paper's tables, the hardware check and
the emulator server, policy probes. The command prints what they return.
"""
