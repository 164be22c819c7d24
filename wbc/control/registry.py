"""The explicit registry of named controllers, and `get_controller`, which resolves every name the arena accepts.

A controller sees only what a real robot gives it (`RobotState`) and the operator's `VelocityCommand`; it never sees
the scenario, the push schedule or simulator truth. Each registered controller names the arm mode it drives, so
``stand-noarm`` runs on the robot without its arm while ``stand`` holds an actuated arm.

Besides the registry's names, `get_controller` resolves:

- ``policy:PATH``: an exported policy file (``wbc train``'s ``policy.npz``, a baseline's, a composite) run by
  `LearnedController`; its robot and arm mode come from the file, so a run of your own meets the shipped controllers
  on the same trials: ``wbc compare learned policy:runs/train/push-stage3-ppo/policy``.
- ``onnx:PATH``: a policy exported to ONNX by another trainer, with the I/O file beside it
  (`wbc.control.onnx_policy`).
- ``package.module:factory``: a plug-in, imported at the moment it is named (`wbc.control.plugin`);
  ``package.module:factory@LABEL`` is the same plug-in under a name of its own, so that one run can play two settings
  of it (each with its own ``--controller-config``). Only such a name takes a label.
- the name of an installed ``wbc.controllers`` entry point (a plug-in a package declares).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import re
from dataclasses import dataclass
from pathlib import Path

from wbc.control.errors import PluginAmbiguousError, PluginConfigError, PluginError, PluginNotFoundError
from wbc.control.onnx_policy import ONNX_PREFIX, onnx_spec
from wbc.control.plugin import (
    ambiguity,
    declared_entry_points,
    entry_point_target,
    label_problem,
    load_plugin,
    plugin_name_problem,
    plugin_spec,
    plugin_target,
)
from wbc.control.spec import ControllerSpec, SourceFile
from wbc.control.stand import StandController
from wbc.errors import ConfigError, UnknownNameError
from wbc.learned.policy.composite_policy import load_composite
from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.policy_file import read_pair
from wbc.learned.policy.shipped import distilled_weights, shipped_weights
from wbc.mpc.controller import MpcController, MpcControllerConfig
from wbc.mpc.tail_controller import TailMpcController
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.registry import ROBOTS, get_robot

__all__ = ["CONTROLLERS", "NAME_FORMS", "ONNX_PREFIX", "POLICY_PREFIX", "ControllerListing", "ControllerSpec",
           "arm_variant", "check_shipped_weights", "get_controller", "list_controllers", "takes_controller_config"]

POLICY_PREFIX = "policy:"
"""``policy:PATH`` names the exported policy at PATH (the .npz, the .json or their stem)."""


def _robots_with_weights(arm_mode: str, posture: str | None = None) -> tuple[str, ...]:
    """The robots, in registry order, whose shipped weights for `arm_mode` (and `posture`) are installed.

    A registry entry that runs shipped weights claims these robots and no others, so ``wbc controllers`` lists them
    and the arena refuses a scenario for another robot before any trial is played.
    """
    return tuple(robot for robot in ROBOTS if shipped_weights(get_robot(robot, arm_mode), posture).is_file())


def _shipped_files(arm_mode: str, posture: str | None = None) -> tuple[SourceFile, ...]:
    """The shipped weights (``.npz``) and their metadata (``.json``) a registry entry runs, for its provenance.

    Paths only: `ControllerSpec.provenance` hashes them when a run asks, so importing the registry reads no weights.
    """
    out = []
    for robot in _robots_with_weights(arm_mode, posture):
        npz = shipped_weights(get_robot(robot, arm_mode), posture)
        out += [SourceFile(role="weights", path=str(npz)),
                SourceFile(role="policy metadata", path=str(npz.with_suffix(".json")))]
    return tuple(out)


def _distilled_robots() -> tuple[str, ...]:
    """The robots, in registry order, for which a policy distilled from the MPC ships (`distilled_weights`)."""
    return tuple(robot for robot in ROBOTS if distilled_weights(get_robot(robot, "actuated")).is_file())


def _distilled_files() -> tuple[SourceFile, ...]:
    """The distilled policies' weights and metadata, for the provenance of a run of ``mpc-distilled``."""
    out = []
    for robot in _distilled_robots():
        npz = distilled_weights(get_robot(robot, "actuated"))
        out += [SourceFile(role="weights", path=str(npz)),
                SourceFile(role="policy metadata", path=str(npz.with_suffix(".json")))]
    return tuple(out)


def _distilled(desc: RobotDescription) -> LearnedController:
    """The policy distilled from ``mpc`` for `desc`'s robot."""
    return LearnedController(desc, distilled_weights(desc))


CONTROLLERS: dict[str, ControllerSpec] = {
    "stand": ControllerSpec("stand", "actuated", StandController,
                            "PD hold of the nominal pose, arm actuated and held"),
    "stand-locked": ControllerSpec("stand-locked", "locked", StandController,
                                   "PD hold of the nominal pose, arm locked"),
    "stand-noarm": ControllerSpec("stand-noarm", "none", StandController,
                                  "PD hold of the nominal pose, robot without its arm"),
    "mpc": ControllerSpec("mpc", "actuated", MpcController,
                          "centroidal MPC with arm momentum terms; the optimiser may swing the arm"),
    "mpc-tail": ControllerSpec("mpc-tail", "actuated", TailMpcController,
                               "centroidal MPC that swings the arm as a tail: arm accelerations planned within the "
                               "servos' torque-speed limits, raised ready pose, re-plans when it detects a push"),
    "mpc-locked": ControllerSpec("mpc-locked", "locked", MpcController, "centroidal MPC, arm locked"),
    "mpc-noarm": ControllerSpec("mpc-noarm", "none", MpcController, "centroidal MPC, robot without its arm"),
    "mpc-wbqp": ControllerSpec("mpc-wbqp", "actuated",
                               functools.partial(MpcController, config=MpcControllerConfig(whole_body="qp")),
                               "centroidal MPC with arm momentum terms, PlaCo's whole-body QP in place of the leg "
                               "layer"),
    "learned": ControllerSpec("learned", "actuated", LearnedController,
                              "learned policy pi3 (PPO + BC, staged), arm actuated; shipped weights, numpy",
                              robots=_robots_with_weights("actuated"), files=_shipped_files("actuated")),
    "learned-locked": ControllerSpec("learned-locked", "locked", LearnedController,
                                     "learned policy pi2, arm locked; shipped weights, numpy",
                                     robots=_robots_with_weights("locked"), files=_shipped_files("locked")),
    "learned-noarm": ControllerSpec("learned-noarm", "none", LearnedController,
                                    "learned policy pi1, robot without its arm; shipped weights, numpy",
                                    robots=_robots_with_weights("none"), files=_shipped_files("none")),
    "mpc-distilled": ControllerSpec("mpc-distilled", "actuated", _distilled,
                                    "policy distilled from mpc by DAgger (wbc train --teacher mpc), arm actuated; "
                                    "shipped weights, numpy", robots=_distilled_robots(), files=_distilled_files()),
    "learned-crouched": ControllerSpec("learned-crouched", "actuated",
                                       functools.partial(LearnedController, posture="crouched"),
                                       "pi3 as first trained (no posture term: crouches), arm actuated; shipped "
                                       "weights", robots=_robots_with_weights("actuated", "crouched"),
                                       files=_shipped_files("actuated", "crouched")),
    "learned-locked-crouched": ControllerSpec("learned-locked-crouched", "locked",
                                              functools.partial(LearnedController, posture="crouched"),
                                              "pi2 as first trained (no posture term: crouches), arm locked; shipped "
                                              "weights", robots=_robots_with_weights("locked", "crouched"),
                                              files=_shipped_files("locked", "crouched")),
    "learned-noarm-crouched": ControllerSpec("learned-noarm-crouched", "none",
                                             functools.partial(LearnedController, posture="crouched"),
                                             "pi1 as first trained (no posture term: crouches), no arm; shipped "
                                             "weights", robots=_robots_with_weights("none", "crouched"),
                                             files=_shipped_files("none", "crouched")),
}


NAME_FORMS = (f"{POLICY_PREFIX}PATH", f"{ONNX_PREFIX}PATH", "package.module:factory")
"""The forms of controller names besides the registry's and the entry points'."""


def check_shipped_weights(spec: ControllerSpec) -> None:
    """Read and check the shipped weights a registry controller plays (`load_composite`: the checksum included).

    A registry entry reads its weights when it is built, in each trial's worker; a run checks them once before it
    plays (`wbc.arena.compare.plan_arena`), as a ``policy:PATH`` file is checked when its name is resolved. Other kinds
    of controller have nothing shipped to check.

    Raises:
        PolicyFileError: a weights file missing, malformed or changed since its export; the message names it.
    """
    if spec.kind != "registry":
        return
    for f in spec.files:
        if f.role == "weights":
            load_composite(f.path)


def get_controller(name: str, *, config: str | Path | None = None, io: str | Path | None = None) -> ControllerSpec:
    """Resolve a controller name: the registry, ``policy:PATH``, ``onnx:PATH``, a plug-in or an entry point.

    Args:
        name: the name.
        config: a ``--controller-config`` TOML file, whose table the plug-in's factory is called with (plug-ins
            only).
        io: the I/O file of an ``onnx:PATH`` policy (default: beside the model).

    Raises:
        UnknownNameError: an unknown name (the message lists the registry's names, the entry points and the forms).
        PluginNotFoundError: a name with a colon, a dot or a path separator that is none of those and not a valid
            ``package.module:factory`` (the message says what is wrong with it, and the name it likely meant); a
            name with an ``@`` that is not ``package.module:factory@LABEL`` with a valid label (`label_problem`).
        PolicyFileError: a ``policy:`` file that is missing or malformed (the message names the file and field).
        OnnxIoError, OnnxModelError: an ``onnx:`` policy's I/O file or model is missing, malformed or mismatched.
        PluginError: a plug-in that cannot be imported or whose factory does not fit (each kind its own subclass).
        PluginAmbiguousError: an entry point's name that several installed distributions declare.
        PluginConfigError: `config` for a controller that is not a plug-in.
        ConfigError: `io` for a controller that is not an ONNX policy; ``policy:`` or ``onnx:`` with no path after it,
            or with a label after an existing file's path.
    """
    if io is not None and not name.startswith(ONNX_PREFIX):
        raise ConfigError(f"--io {io}: an I/O file describes an onnx:PATH policy, and {name} is not one")
    if config is not None and not takes_controller_config(name):
        raise PluginConfigError(f"--controller-config {config}: {name} takes no configuration table; it goes to "
                                "plug-ins (package.module:factory, or an entry point's name)")
    for prefix, what in ((POLICY_PREFIX, "a policy file (its .npz / .json pair, with or without the suffix)"),
                         (ONNX_PREFIX, "an .onnx model")):
        if name.startswith(prefix) and not Path(name[len(prefix):]).name:
            raise ConfigError(f"controller {name!r}: {prefix} needs the path of {what} after it, e.g. "
                              f"{prefix}runs/my-policy{'.onnx' if prefix == ONNX_PREFIX else ''}")
    _refuse_file_label(name)
    if name.startswith(POLICY_PREFIX):
        return _policy_spec(name)
    if name.startswith(ONNX_PREFIX):
        return onnx_spec(name, name[len(ONNX_PREFIX):], io)
    if name in CONTROLLERS:
        return CONTROLLERS[name]
    target = plugin_target(name)  # package.module:factory, labelled or not
    if target is not None:
        return plugin_spec(name, target, config_file=config)
    installed = declared_entry_points()
    if name in installed:
        if len(installed[name]) > 1:
            raise PluginAmbiguousError(ambiguity(name, installed[name]))
        (ep,) = installed[name]
        return plugin_spec(name, entry_point_target(ep), kind="entry point", config_file=config, entry_point=ep)
    if "@" in name:
        raise PluginNotFoundError(label_problem(name, registry=CONTROLLERS, entry_points={
            n: eps[0].value.partition("[")[0].strip() for n, eps in installed.items() if len(eps) == 1}))
    usable = [n for n, eps in installed.items()  # not shadowed by the registry or a name form, not ambiguous
              if len(eps) == 1 and n not in CONTROLLERS and _reserved_form(n) is None]
    if Path(name).suffix.lower() == ".toml":
        raise UnknownNameError("controller", name, (*CONTROLLERS, *usable, *NAME_FORMS),
                               where="a TOML file is not a controller (a scenario goes after --scenario, a plug-in's "
                                     "table after --controller-config)")
    problem = plugin_name_problem(name)  # a plug-in meant (a colon, a dot, a path), but written wrong
    def plain(text: str) -> str:  # a name with its separators alike: mpc.tail ~ mpc-tail, my.dottd ~ my.dotted
        return re.sub(r"[._-]", "-", text)

    if problem is not None and not difflib.get_close_matches(plain(name), [plain(n) for n in (*CONTROLLERS, *usable)],
                                                             n=1, cutoff=0.85):
        raise PluginNotFoundError(problem)
    raise UnknownNameError("controller", name, (*CONTROLLERS, *usable, *NAME_FORMS))  # a typo of a name suggests it


def _refuse_file_label(name: str) -> None:
    """Refuse ``policy:PATH@LABEL`` / ``onnx:PATH@LABEL``: a file that exists, with a label after it.

    The text after ``policy:`` or ``onnx:`` is a path, ``@`` and all (a file may be named with one); it is read as
    a label only when no file has the whole name and one has the name before its last ``@``.

    Raises:
        ConfigError: `name` is such a name; the message says where a label goes and names the file alone.
    """
    for prefix, suffixes in ((POLICY_PREFIX, ("", ".npz")), (ONNX_PREFIX, ("",))):
        if not name.startswith(prefix):
            continue
        path = name[len(prefix):]
        head, at, _ = path.rpartition("@")
        if at and _is_file(head, suffixes) and not _is_file(path, suffixes):
            raise ConfigError(
                f"controller {name!r}: {prefix}PATH names a file, and a label (NAME@LABEL) tells apart two settings "
                "of one plug-in, named package.module:factory@LABEL, each with its own --controller-config; a "
                f"policy file takes no settings, so a label means nothing there: name it {prefix}{head}")


def _is_file(path: str, suffixes: tuple[str, ...]) -> bool:
    """Whether `path`, with one of `suffixes` added, is a file."""
    return bool(path) and any(Path(path + suffix).is_file() for suffix in suffixes)


def _reserved_form(name: str) -> str | None:
    """Why an entry point's `name` can never name it, or None: a form `get_controller` resolves before entry points.

    A name that starts with ``policy:`` or ``onnx:`` names a file, and one of the form ``package.module:factory`` a
    plug-in imported by that path; such an entry point is never reached, as one with a registry name is not.
    """
    for prefix, form in ((POLICY_PREFIX, "a policy file"), (ONNX_PREFIX, "an ONNX policy")):
        if name.startswith(prefix):
            return (f"{name!r} has the form {prefix}PATH, which names {form} ({name[len(prefix):]!r}), never an "
                    "entry point; declare it under a name without a colon")
    if plugin_target(name) is not None:
        return (f"{name!r} has the form package.module:factory, which imports the module {name.partition(':')[0]!r}, "
                "never an entry point; declare it under a name without a colon")
    return None


def _policy_spec(name: str) -> ControllerSpec:
    path = name[len(POLICY_PREFIX):]
    policy = load_composite(path)  # the whole file is read and checked here, once, before any trial starts
    npz, js, _ = read_pair(path)
    meta = policy.meta
    return ControllerSpec(name, meta["arm_mode"], functools.partial(LearnedController, policy_path=path, policy=policy),
                          f"policy file {path} ({meta['task']} task, stage {meta['stage']})", robots=(meta["robot"],),
                          kind="policy file",
                          files=(SourceFile.hashed("weights", npz), SourceFile.hashed("policy metadata", js)))


def arm_variant(spec: ControllerSpec, arm_mode: str) -> ControllerSpec:
    """The registered controller that does what `spec` does on a robot with arm mode `arm_mode`.

    Variants are the entries built by the same factory (``stand``, ``stand-locked`` and ``stand-noarm`` are all the
    stand controller), so a hardware trial can name a controller as the arena does and play it on the arm the robot
    has: ``stand`` with the arm ``none`` is ``stand-noarm``. A plug-in that claims `arm_mode` among its arm modes
    (`ControllerSpec.arm_modes`) is played in that mode.

    Raises:
        UnknownNameError: `arm_mode` is not an arm mode.
        ConfigError: `spec` has no variant for `arm_mode` (a policy file drives the arm mode it was trained on).
    """
    check_arm_mode(arm_mode)
    if spec.arm_mode == arm_mode:
        return spec
    if arm_mode in spec.arm_modes:  # a plug-in that claims several arm modes is its own variant
        return dataclasses.replace(spec, arm_mode=arm_mode)
    variants = [s for s in CONTROLLERS.values() if s.make is spec.make]
    for variant in variants:
        if variant.arm_mode == arm_mode:
            return variant
    have = ", ".join(f"{s.name} ({s.arm_mode})" for s in variants) or f"{spec.name} ({spec.arm_mode})"
    raise ConfigError(f"controller {spec.name} drives the arm mode {spec.arm_mode}, and no variant of it drives "
                      f"{arm_mode!r} (variants: {have}); choose the arm mode it was made for, or another controller")


def takes_controller_config(name: str) -> bool:
    """Whether `name` is a plug-in's (a ``module:factory`` or an entry point), the only kind a config table goes to."""
    return name not in CONTROLLERS and not name.startswith((POLICY_PREFIX, ONNX_PREFIX))


@dataclass(frozen=True, kw_only=True)
class ControllerListing:
    """One row of ``wbc controllers``.

    Attributes:
        name: the controller's name.
        kind: ``registry`` or ``entry point``.
        arm_modes: the arm modes it drives (the first is played); empty when it could not be loaded.
        robots: the robots it drives, or None for every robot.
        summary: its one-line summary, or why it could not be loaded.
        target: an entry point's ``module:factory`` (its value as declared, for one that names no factory), else
            None (also for a name several distributions declare).
        loaded: False for an entry point whose plug-in could not be loaded.
    """

    name: str
    kind: str
    arm_modes: tuple[str, ...]
    robots: tuple[str, ...] | None
    summary: str
    target: str | None = None
    loaded: bool = True


def list_controllers() -> list[ControllerListing]:
    """The registry's controllers, then every installed ``wbc.controllers`` entry point.

    An entry point that a registry name or a name form (`_reserved_form`) shadows is listed as not usable, with why.

    Each entry point is imported to read its summary; one that fails to load is listed with its error instead of
    stopping the listing, and a name several distributions declare is listed once, with who declares it.
    """
    rows = [ControllerListing(name=s.name, kind="registry", arm_modes=s.arm_modes, robots=s.robots, summary=s.summary)
            for s in CONTROLLERS.values()]
    for name, eps in sorted(declared_entry_points().items()):
        ep = eps[0]
        target = ep.value
        if name in CONTROLLERS:
            rows.append(ControllerListing(name=name, kind="entry point", arm_modes=(), robots=None, target=target,
                                          summary=f"not usable: the registry's {name!r} has this name", loaded=False))
            continue
        reserved = _reserved_form(name)
        if reserved is not None:
            rows.append(ControllerListing(name=name, kind="entry point", arm_modes=(), robots=None, target=target,
                                          summary=f"not usable: {reserved}", loaded=False))
            continue
        if len(eps) > 1:
            rows.append(ControllerListing(name=name, kind="entry point", arm_modes=(), robots=None, target=None,
                                          summary=f"not usable: {ambiguity(name, eps)}", loaded=False))
            continue
        try:
            target = entry_point_target(ep)
            plugin, _ = load_plugin(target)
        except PluginError as exc:
            rows.append(ControllerListing(name=name, kind="entry point", arm_modes=(), robots=None, target=target,
                                          summary=f"cannot be loaded: {exc}", loaded=False))
            continue
        rows.append(ControllerListing(name=name, kind="entry point", arm_modes=plugin.arm_modes, robots=plugin.robots,
                                      summary=plugin.summary, target=target))
    return rows
