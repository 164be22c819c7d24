"""What a policy call of our form costs when its networks are made small, beside `mpc` and `mpc-distilled`.

Run: python benchmarks/policy_call_floor.py [--networks 8:1:1 64,32:8:5] [--repeats 3]
Each ``ACTOR:MEMORY:HISTORY`` builds a timing-only policy ``aACTOR_mMEMORY_wHISTORY`` in a temporary directory: the
shipped a1-wx200 `mpc-distilled`'s observation, normaliser, gains and action form, with an actor of the hidden
layers ACTOR, an adaptation module of the hidden layers MEMORY reading a window of HISTORY observations, and random
weights (it stands, then falls at the first push: a call costs the same on any state). ``wbc bench act`` then times
every controller on push v2 band ``in``, seed 0, trial 0, taking turns, and the last line sets the cheapest call
against a tenth of `mpc`'s mean call. What such networks leave is the call's own work: the observation, the
normaliser, the window, the clip and the command.
"""

from __future__ import annotations

import argparse
import copy
import os
import tempfile
from pathlib import Path

import numpy as np

from wbc.cli import printers
from wbc.cli.parser import bounded_int
from wbc.errors import WbcError
from wbc.learned.policy.policy_file import PolicyFile, load_policy, save_policy
from wbc.tools.bench.act import bench_act

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "wbc" / "learned" / "weights" / "a1-wx200-actuated-mpc-distilled"
"""The policy whose form the timing-only policies take."""


def _layers(text: str) -> list[int]:
    sizes = [int(s) for s in text.split(",")] if text else []
    if any(not 1 <= s <= 4096 for s in sizes):
        raise ValueError(text)
    return sizes


def network(text: str) -> tuple[list[int], list[int], int]:
    """``ACTOR:MEMORY:HISTORY`` as (actor's hidden sizes, memory's hidden sizes, window length)."""
    try:
        actor, memory, history = text.split(":")
        sizes = _layers(actor), _layers(memory), int(history)
        if not sizes[0] or not 1 <= sizes[2] <= 200:
            raise ValueError(text)
        return sizes
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give ACTOR:MEMORY:HISTORY, hidden sizes 1..4096 comma-separated (the actor's at least one) "
            "and a window of 1..200 observations, e.g. 64,32:8:5") from None


def timing_policy(source: PolicyFile, actor: list[int], memory: list[int], history: int, seed: int) -> PolicyFile:
    """`source`'s form with networks of these sizes and random weights (std 0.01, zero biases)."""
    rng = np.random.default_rng(seed)
    meta = copy.deepcopy(source.meta)
    meta.pop("weights_sha256", None)
    meta.pop("training", None)
    meta["hidden_dims"] = actor
    meta["adaptation"] = dict(meta["adaptation"], hidden_dims=memory, history=history)
    obs = source.arrays["obs_mean"].size
    latent = int(meta["extrinsics"]["dim"])
    arrays = {"obs_mean": source.arrays["obs_mean"], "obs_std": source.arrays["obs_std"]}
    for prefix, dims in (("policy", [obs + latent, *actor, int(meta["num_actions"])]),
                         ("adaptation", [obs * history, *memory, latent])):
        for i, (n_in, n_out) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
            arrays[f"{prefix}/{i}/weight"] = rng.normal(0.0, 0.01, (n_out, n_in))
            arrays[f"{prefix}/{i}/bias"] = np.zeros(n_out)
    return PolicyFile(meta=meta, arrays=arrays)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--networks", type=network, nargs="+", default=[network("8:1:1"), network("64,32:8:5")],
                        metavar="ACTOR:MEMORY:HISTORY")
    parser.add_argument("--repeats", type=bounded_int(1, 20), default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        names = []
        try:
            source = load_policy(SOURCE)
            for k, (actor, memory, history) in enumerate(args.networks):
                name = f"a{'-'.join(map(str, actor))}_m{'-'.join(map(str, memory)) or 0}_w{history}"
                save_policy(Path(tmp) / name, timing_policy(source, actor, memory, history, seed=k))
                names.append(f"policy:{name}")
            os.chdir(tmp)  # the policies by short relative names, for the table
            result = bench_act(["mpc", "mpc-distilled", *names], scenario=str(ROOT / "scenarios" / "push.toml"),
                               repeats=args.repeats)
        except WbcError as exc:
            parser.exit(2, f"policy_call_floor: error: {exc}\n")
    printers.print_bench_act(result)
    mpc, cheapest = result.costs[0], min(result.costs[2:], key=lambda c: c.cpu_us_per_tick_mean)
    print(f"a tenth of {mpc.controller}'s mean call: {mpc.cpu_us_per_tick_mean / 10:.1f} us; the cheapest timing-only "
          f"policy's call: {cheapest.cpu_us_per_tick_mean:.1f} us mean, "
          f"{cheapest.cpu_us_per_tick_mean / mpc.cpu_us_per_tick_mean:.3f} of {mpc.controller}'s")


if __name__ == "__main__":
    main()
