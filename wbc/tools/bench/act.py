"""``wbc bench act``: what each controller's ``act`` costs in CPU, on the same trial, in one run.

Controllers run at their own rates (the MPC at 500 Hz, the policies at 50 Hz), so two figures answer "what does it
cost": the CPU time of one ``act`` call (a control tick of its own rate), and the CPU time its ``act`` calls take per
simulated second. Each controller plays the same trial of a scenario (`run_trial`, as the arena plays it); its
``act`` is timed with the calling thread's CPU clock (`time.thread_time`: time the process waits for a core does not
count, so a busy machine changes the figures less than it changes wall time). The controllers take turns, `repeats`
rounds of one trial each, so that a change of the machine's load falls on all of them alike; each figure is the
round with the least CPU per simulated second. Ratios are stated against the first controller, measured in the same
run.

A trial in which a controller falls ends early: its figures cover the time it stood (``survived_s``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wbc.arena.controller_failure import ControllerFailure
from wbc.arena.sim_trial import run_trial
from wbc.control.registry import get_controller
from wbc.control.spec import ControllerSpec
from wbc.errors import BenchError
from wbc.robots.description import RobotDescription
from wbc.scenario.scenario import load_scenario
from wbc.tools.bench.references import load_1min, machine_description

__all__ = ["ActBenchResult", "ActCost", "bench_act"]


@dataclass(frozen=True, kw_only=True)
class ActCost:
    """One controller's ``act`` cost on the trial (the round with the least CPU per simulated second).

    Attributes:
        controller: the controller's name.
        rate_hz: its control rate [Hz].
        ticks: ``act`` calls in the trial.
        survived_s: simulated time played [s] (the trial's length unless it fell).
        fell: whether it fell in that round.
        cpu_us_per_tick_median: median CPU time of one ``act`` [us].
        cpu_us_per_tick_mean: mean CPU time of one ``act`` [us].
        cpu_ms_per_s: CPU time of all its ``act`` calls per simulated second [ms/s].
        rounds: rounds played.
    """

    controller: str
    rate_hz: float
    ticks: int
    survived_s: float
    fell: bool
    cpu_us_per_tick_median: float
    cpu_us_per_tick_mean: float
    cpu_ms_per_s: float
    rounds: int


@dataclass(frozen=True, kw_only=True)
class ActBenchResult:
    """What `bench_act` measured.

    Attributes:
        scenario: the scenario file.
        band: the trial's band.
        seed: the trial's seed.
        trial: the trial's index.
        costs: one per controller, in the order given; the first is the reference of the ratios.
        machine: the machine (`machine_description`).
        load_1min: the 1-minute load average at the end (nan where unknown).
    """

    scenario: str
    band: str
    seed: int
    trial: int
    costs: tuple[ActCost, ...]
    machine: str
    load_1min: float

    def ratios(self) -> list[tuple[str, float, float]]:
        """(controller, mean CPU per ``act`` over the reference's mean, CPU per simulated second over its)."""
        ref = self.costs[0]
        return [(c.controller, c.cpu_us_per_tick_mean / ref.cpu_us_per_tick_mean, c.cpu_ms_per_s / ref.cpu_ms_per_s)
                for c in self.costs]

    def as_dict(self) -> dict[str, object]:
        """Plain dict, keys as the attributes' names, with the ratios against the first controller.

        Each ratio's ``per_tick`` is the mean CPU per ``act`` over the first controller's mean (`ratios`), and its
        ``per_simulated_s`` the CPU per simulated second over the first controller's.
        """
        out = dataclasses.asdict(self)
        out["costs"] = [dataclasses.asdict(c) for c in self.costs]
        out["ratios"] = [{"controller": name, "per_tick": tick, "per_simulated_s": second}
                         for name, tick, second in self.ratios()]
        return out


class _ActClock:
    """Wraps a spec's `make`: the controller it builds has its ``act`` timed on the thread's CPU clock."""

    def __init__(self, spec: ControllerSpec) -> None:
        self._make = spec.make
        self.name = spec.name
        self.cpu_s: list[float] = []
        self.rate_hz = float("nan")

    def __call__(self, desc: RobotDescription) -> object:
        ctrl = self._make(desc)
        act, clock, out = ctrl.act, time.thread_time, self.cpu_s

        def timed(state: object, command: object) -> object:
            start = clock()
            try:
                return act(state, command)
            finally:
                out.append(clock() - start)

        try:
            ctrl.act = timed  # type: ignore[method-assign]
        except AttributeError as exc:  # a class with __slots__ and no __dict__
            raise BenchError(f"bench act cannot time controller {self.name!r}: its act cannot be wrapped ({exc})") \
                from exc
        self.rate_hz = float(ctrl.rate_hz)
        return ctrl


def bench_act(controllers: Sequence[str], *, scenario: str = "scenarios/push.toml", band: str = "in", seed: int = 0,
              trial: int = 0, repeats: int = 3) -> ActBenchResult:
    """CPU per ``act`` call and per simulated second of each controller on one trial, taking turns.

    Args:
        controllers: controller names (`get_controller`: registry names, ``policy:PATH``, plug-ins); the first is
            the reference of the ratios.
        scenario: the scenario file.
        band: the trial's band.
        seed: the trial's seed.
        trial: the trial's index in its band and seed.
        repeats: rounds, each controller one trial a round.

    Returns:
        Each controller's figures from its round with the least CPU per simulated second.

    Raises:
        BenchError: no controllers, or a controller failed in the trial (its error).
        UnknownNameError: an unknown controller.
        ScenarioError: the scenario, band or trial does not exist.
    """
    if not controllers:
        raise BenchError("bench act needs at least one controller")
    sc = load_scenario(scenario)
    the_trial = sc.trial(band, seed, trial)
    specs = [get_controller(name) for name in controllers]
    best: dict[int, ActCost] = {}
    for _ in range(max(1, repeats)):
        for k, spec in enumerate(specs):
            clock = _ActClock(spec)
            try:
                _, episode = run_trial(the_trial, dataclasses.replace(spec, make=clock), record_errors=False)
            except ControllerFailure as exc:
                raise BenchError(f"bench act: controller {spec.name!r} failed in the trial: {exc}") from exc
            if not clock.cpu_s:
                raise BenchError(f"bench act: {spec.name} was never asked to act in the trial")
            cpu = np.asarray(clock.cpu_s)
            survived = float(episode.survived_s)
            cost = ActCost(controller=spec.name, rate_hz=clock.rate_hz, ticks=len(cpu), survived_s=survived,
                           fell=bool(episode.fell), cpu_us_per_tick_median=1e6 * float(np.median(cpu)),
                           cpu_us_per_tick_mean=1e6 * float(cpu.mean()),
                           cpu_ms_per_s=1e3 * float(cpu.sum()) / max(survived, 1e-9),
                           rounds=(best[k].rounds + 1) if k in best else 1)
            if k not in best or cost.cpu_ms_per_s < best[k].cpu_ms_per_s:
                best[k] = cost
            else:
                best[k] = dataclasses.replace(best[k], rounds=cost.rounds)
    load = load_1min()
    return ActBenchResult(scenario=scenario, band=band, seed=seed, trial=trial,
                          costs=tuple(best[k] for k in range(len(specs))), machine=machine_description(),
                          load_1min=load)
