"""`ControllerSpec`: a controller resolved from its name, ready to be built for a robot (and pickled to a worker).

Every name the arena accepts (a registry name, ``policy:PATH``, ``onnx:PATH``, ``package.module:factory``, an entry
point) resolves to one of these (`wbc.control.registry.get_controller`). The spec says which robots and arm modes the
controller claims, and its `make` builds it for a robot description. `make` must pickle: the local pool and Ray
workers receive the spec, not the name, so a name is resolved (and any file it names is read) once, in the parent.

A spec also says what the controller *is*, for the record a run keeps (`ControllerSpec.provenance`): the files its
behaviour comes from (weights, an ONNX model and its external data, an I/O or configuration file), each with its
sha256, and for a plug-in the ``module:factory`` it was imported from, the module's file and the distribution (name and
version) that installed it. Files are hashed once per spec: when the resolver hashes them (`SourceFile.hashed`, the
files it read anyway) or at the first `provenance` call.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from wbc.control.protocol import Controller
from wbc.robots.description import RobotDescription, check_arm_mode
from wbc.robots.registry import ROBOTS

__all__ = ["NO_DISTRIBUTION", "ControllerSpec", "PluginSource", "SourceFile", "distribution_of", "sha256_file"]

NO_DISTRIBUTION = "not installed as a distribution"
"""What `PluginSource.describe` says of a module found on ``sys.path`` that no installed distribution provides."""

_CHUNK = 1 << 20


def sha256_file(path: str | Path) -> str:
    """The sha256 (hex) of a file's bytes, read in 1 MiB chunks.

    Raises:
        OSError: the file cannot be read.
    """
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


@dataclass(frozen=True, kw_only=True)
class SourceFile:
    """A file a controller's behaviour comes from.

    Attributes:
        role: what it holds: ``weights``, ``policy metadata``, ``model``, ``external data``, ``io`` or ``config``.
        path: the file, absolute.
        sha256: its content hash (hex), or None until `ControllerSpec.provenance` hashes it.
    """

    role: str
    path: str
    sha256: str | None = None

    @classmethod
    def hashed(cls, role: str, path: str | Path) -> SourceFile:
        """The file, hashed now (for a file the resolver has just read).

        Raises:
            OSError: the file cannot be read.
        """
        resolved = Path(path).resolve()
        return cls(role=role, path=str(resolved), sha256=sha256_file(resolved))


def distribution_of(module: str, module_file: str | None) -> tuple[str, str] | None:
    """The installed distribution (name, version) that provides `module`, or None for a loose module.

    A distribution provides the module when it declares the module's top-level package
    (`importlib.metadata.packages_distributions`) and either lists the module's file among its files or is an editable
    install of the directory holding it; a same-named package elsewhere on ``sys.path`` is not credited to it.

    Args:
        module: the dotted module name.
        module_file: the module's file (``module.__file__``), or None.
    """
    if module_file is None:
        return None
    top = module.split(".")[0]
    where = Path(module_file).resolve()
    for name in importlib.metadata.packages_distributions().get(top, []):
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            continue
        files = {Path(str(dist.locate_file(f))).resolve() for f in dist.files or ()}
        if where in files or _editable_root_holds(dist, where):
            return dist.metadata["Name"], dist.version
    return None


def _editable_root_holds(dist: importlib.metadata.Distribution, where: Path) -> bool:
    """Whether `dist` is an editable install (PEP 660 ``direct_url.json``) of a directory that holds `where`."""
    text = dist.read_text("direct_url.json")
    if not text:
        return False
    try:
        info = json.loads(text)
    except ValueError:
        return False
    url = info.get("url", "") if isinstance(info, dict) else ""
    if not (isinstance(info.get("dir_info"), dict) and info["dir_info"].get("editable")) or \
            not url.startswith("file://"):
        return False
    return where.is_relative_to(Path(url[len("file://"):]).resolve())


@dataclass(frozen=True, kw_only=True)
class PluginSource:
    """Where a plug-in's code comes from.

    Attributes:
        target: ``package.module:factory``.
        module_file: the module's file, or None (a namespace package, a built-in module).
        entry_point: the ``wbc.controllers`` entry point's name, or None for a ``module:factory`` name.
        distribution: (name, version) of the distribution that declares the entry point, or None: then it is looked
            up from the module (`distribution_of`) when `describe` is called.
    """

    target: str
    module_file: str | None
    entry_point: str | None = None
    distribution: tuple[str, str] | None = None

    def describe(self) -> dict[str, object]:
        """What the plug-in is, JSON-ready.

        Returns:
            ``target``, ``module_file``, ``module_sha256`` (its bytes' hash, None when it is not a readable file),
            ``entry_point``, ``distribution`` ({name, version}, or None; then ``distribution_note`` says the module
            is not installed as a distribution).
        """
        dist = self.distribution
        if dist is None:
            module = self.target.split(":")[0]
            loaded = sys.modules.get(module)
            dist = distribution_of(module, getattr(loaded, "__file__", None) or self.module_file)
        module_sha256 = None
        if self.module_file is not None:
            try:
                module_sha256 = sha256_file(self.module_file)
            except OSError:
                pass  # not a file on disk (a zip import, say): the distribution and its version stand for it
        out: dict[str, object] = {"target": self.target, "module_file": self.module_file,
                                  "module_sha256": module_sha256, "entry_point": self.entry_point,
                                  "distribution": None if dist is None else {"name": dist[0], "version": dist[1]}}
        if dist is None:
            out["distribution_note"] = NO_DISTRIBUTION
        return out


def _wbc_version() -> str | None:
    try:
        return importlib.metadata.version("wbc")
    except importlib.metadata.PackageNotFoundError:
        return None


@dataclass(frozen=True)
class ControllerSpec:
    """A resolved controller.

    Attributes:
        name: the name it was given by (a registry name, ``policy:PATH``, ``module:factory`` ...).
        arm_mode: the arm mode the arena plays it with (``none``, ``locked``, ``actuated``).
        make: builds the controller for a robot description.
        summary: one line for listings and reports.
        robots: the robots it can drive, or None for every robot of `wbc.robots.registry.ROBOTS`.
        arm_modes: every arm mode it can drive, `arm_mode` first (default: `arm_mode` only).
        kind: where the name came from: ``registry``, ``policy file``, ``onnx``, ``plug-in`` or ``entry point``.
        config_file: the configuration file it was built with (``--controller-config``, ``--io``), or None.
        files: the files its behaviour comes from (`provenance` hashes those not hashed yet).
        plugin: where a plug-in's code comes from, or None for every other kind.
    """

    name: str
    arm_mode: str
    make: Callable[[RobotDescription], Controller]
    summary: str
    robots: tuple[str, ...] | None = field(default=None, kw_only=True)
    arm_modes: tuple[str, ...] = field(default=(), kw_only=True)
    kind: str = field(default="registry", kw_only=True)
    config_file: str | None = field(default=None, kw_only=True)
    files: tuple[SourceFile, ...] = field(default=(), kw_only=True)
    plugin: PluginSource | None = field(default=None, kw_only=True)
    _memo: dict[str, object] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_arm_mode(self.arm_mode)
        modes = tuple(dict.fromkeys((self.arm_mode, *self.arm_modes)))  # arm_mode first, no repeats
        for mode in modes:
            check_arm_mode(mode)
        object.__setattr__(self, "arm_modes", modes)
        if self.robots is not None:
            object.__setattr__(self, "robots", tuple(self.robots))
        object.__setattr__(self, "files", tuple(self.files))

    @property
    def robot(self) -> str | None:
        """The only robot it can drive (a policy file's), or None when it drives several or every robot."""
        return self.robots[0] if self.robots is not None and len(self.robots) == 1 else None

    def claims(self) -> list[tuple[str, str]]:
        """Every (robot, arm mode) this controller says it can drive, robots in registry order."""
        robots = self.robots if self.robots is not None else tuple(ROBOTS)
        return [(robot, mode) for robot in robots for mode in self.arm_modes]

    def drives(self, robot: str) -> bool:
        """Whether it claims `robot` (a registry name)."""
        return self.robots is None or robot in self.robots

    def provenance(self) -> dict[str, object]:
        """What this controller is, for a run's record (``run.json``); JSON-ready.

        Returns:
            ``name``, ``kind``, ``arm_mode``, ``wbc_version`` (the installed wbc's, None outside an install),
            ``files``: ``[{role, path, sha256}]`` (weights and their metadata, an ONNX model, its external data
            files and its I/O file, a configuration file; empty for code-only controllers such as ``stand`` and
            ``mpc``), and for a plug-in or an entry point ``plugin``: ``{target, module_file, entry_point,
            distribution: {name, version} | None, distribution_note}`` (`PluginSource.describe`). A file is hashed
            at most once per spec; a file that cannot be read has ``sha256`` None and an ``error``.
        """
        files = []
        for f in self.files:
            entry: dict[str, object] = {"role": f.role, "path": f.path, "sha256": f.sha256}
            if f.sha256 is None:
                key = f"sha256:{f.path}"
                if key not in self._memo:
                    try:
                        self._memo[key] = sha256_file(f.path)
                    except OSError as exc:
                        entry["error"] = f"{type(exc).__name__}: {exc}"
                entry["sha256"] = self._memo.get(key)
            files.append(entry)
        out: dict[str, object] = {"name": self.name, "kind": self.kind, "arm_mode": self.arm_mode,
                                  "wbc_version": _wbc_version(), "files": files}
        if self.plugin is not None:
            if "plugin" not in self._memo:  # the distribution look-up scans the environment: once per spec
                self._memo["plugin"] = self.plugin.describe()
            out["plugin"] = dict(self._memo["plugin"])  # type: ignore[call-overload]
        return out
