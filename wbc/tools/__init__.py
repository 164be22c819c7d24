"""Tools on top of the arena: speed benches, the tail analysis, the arm-momentum study, policy probes."""
