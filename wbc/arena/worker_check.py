"""A Ray worker's check, before it plays a trial, that it runs what the driver recorded.

A Ray worker imports wbc and opens a controller's files (an ONNX model, policy weights, a plug-in's module) from its
own node's disk. A node with another wbc commit or other wbc files (outside a git checkout too: the hash of the
package's files), other versions of the packages that change results, or a changed or
missing controller file would play other trials than the driver's ``run.json`` says, and did so silently; a file
missing there was recorded as the controller's error. The driver sends each task what it recorded
(`Expectation`: its own `fingerprint` and the controller's files with their sha256), and the worker compares it with
its own before it builds the controller (`check_worker`). A difference raises `wbc.errors.ClusterError`, which names the
node, the package or file, and both values: the run stops, no trial is recorded for it, and ``--resume`` finishes it
once the cluster is fixed.

The worker's fingerprint is read once per worker process (it asks git), and a file's hash once per file as long as
its size and time do not change: a worker playing trial after trial pays for neither again.
"""

from __future__ import annotations

import functools
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path

from wbc.control.spec import ControllerSpec, sha256_file
from wbc.errors import ClusterError
from wbc.provenance import RESULT_PACKAGES, provenance

__all__ = ["Expectation", "check_worker", "expectation", "fingerprint", "node_name", "without_colour"]

_RESUME = ("the run stops here, no trial recorded for it: the trials stored are kept, and --resume finishes the run "
           "once the cluster is fixed")
"""How every refusal of a worker ends."""


@dataclass(frozen=True, kw_only=True)
class Expectation:
    """What a worker must run for one controller, as the driver recorded it.

    Attributes:
        environment: the driver's `fingerprint`: (what, value) pairs.
        files: the controller's files, (path, sha256), as ``run.json`` records them.
        module: a plug-in's (module, file, sha256 of the file), file and hash None where the driver had none; None
            for every other kind of controller.
    """

    environment: tuple[tuple[str, str | None], ...]
    files: tuple[tuple[str, str], ...] = ()
    module: tuple[str, str | None, str | None] | None = None


@functools.cache
def fingerprint() -> tuple[tuple[str, str | None], ...]:
    """This process's wbc (version, revision, uncommitted changes, files' hash) and result-changing packages' versions.

    The files' hash (`wbc.provenance.package_sha256`) tells apart two installs that git cannot: a wheel, a copied
    tree, a node's own copy edited in place.

    Read once per process (`wbc.provenance.provenance`); a package not installed is None.
    """
    env = provenance()
    packages = env.get("packages")
    packages = packages if isinstance(packages, dict) else {}
    diff, files = env.get("git_diff_sha256"), env.get("wbc_sha256")
    return (("wbc version", packages.get("wbc")), ("wbc git revision", str(env.get("git_revision"))),
            ("wbc uncommitted changes (sha256)", None if diff is None else str(diff)),
            ("wbc package files (sha256)", None if files is None else str(files)),
            *((f"package {name}", packages.get(name)) for name in RESULT_PACKAGES))


def expectation(spec: ControllerSpec) -> Expectation:
    """What a worker must run to play `spec`, from this (the driver's) process and `spec`'s recorded files."""
    record = spec.provenance()
    files = tuple((_portable(str(f["path"])), str(f["sha256"])) for f in record["files"]  # type: ignore[union-attr]
                  if f.get("sha256") is not None)
    module = None
    plugin = record.get("plugin")
    if isinstance(plugin, dict):
        module = (str(plugin["target"]).split(":")[0], plugin.get("module_file"), plugin.get("module_sha256"))
    return Expectation(environment=fingerprint(), files=files, module=module)


_PACKAGE = Path(__file__).resolve().parents[1]
"""This process's wbc package directory: the shipped files (weights) lie under it, wherever it is installed."""

_IN_PACKAGE = "wbc-package:"
"""How `Expectation.files` names a file shipped inside the wbc package: by its path within the package, so that a
node with the same wbc installed at another path (a container's /home/ray/wbc, the driver's checkout elsewhere) finds
it; its sha256 is checked all the same."""


def _portable(path: str) -> str:
    """`path` as a worker finds it: a file inside this wbc package by its path within it, any other as it is."""
    try:
        return _IN_PACKAGE + Path(path).resolve().relative_to(_PACKAGE).as_posix()
    except ValueError:
        return path


def _local(path: str) -> str:
    """A path of `Expectation.files` on this node (`_portable`'s inverse, against this node's wbc package)."""
    return str(_PACKAGE / path.removeprefix(_IN_PACKAGE)) if path.startswith(_IN_PACKAGE) else path


def node_name() -> str:
    """This node, as a refusal names it: its host name, and its address in the Ray cluster where one runs."""
    host = socket.gethostname()
    try:
        import ray.util  # only on a Ray worker: the local pool never asks

        return f"{host} ({ray.util.get_node_ip_address()})"
    except Exception:  # noqa: BLE001 - no Ray, or not in one: the host name alone
        return host


def check_worker(expected: Expectation) -> None:
    """Refuse to play on this worker unless it runs what the driver recorded.

    Raises:
        ClusterError: this worker's wbc or a result-changing package differs from the driver's, or a controller
            file (or a plug-in's module) differs or is missing here; the message names this node, what differs and
            both values.
    """
    mine = dict(fingerprint())
    for what, driver in expected.environment:
        if mine.get(what) != driver:
            raise ClusterError(f"worker node {node_name()} runs another {what} than the driver: {mine.get(what)} "
                               f"there, {driver} on the driver (as run.json records it); install the driver's wbc "
                               f"checkout and locked packages on every node; {_RESUME}")
    for path, sha256 in expected.files:
        _check_file(_local(path), sha256, "controller file")
    if expected.module is not None:
        _check_module(*expected.module)


def _check_file(path: str, sha256: str, what: str) -> None:
    try:
        stat = os.stat(path)
    except OSError as exc:
        raise ClusterError(f"worker node {node_name()} has no {what} {path} ({exc.strerror or exc}); the driver "
                           f"recorded it with sha256 {sha256}: every node needs the controller's files at the same "
                           f"absolute paths; {_RESUME}") from None
    found = _sha256(path, stat.st_size, stat.st_mtime_ns)
    if found != sha256:
        raise ClusterError(f"worker node {node_name()} has another {what} {path}: sha256 {found} there, {sha256} on "
                           f"the driver (as run.json records it); copy the driver's file to every node; {_RESUME}")


def _check_module(module: str, module_file: str | None, sha256: str | None) -> None:
    """A plug-in's module: the worker imports it from the directory the driver found it in (`PluginFactory`)."""
    if module_file is None or sha256 is None:  # a namespace package, or no file the driver could read
        return
    _check_file(module_file, sha256, f"plug-in module {module} file")


@functools.lru_cache(maxsize=256)
def _sha256(path: str, size: int, mtime_ns: int) -> str:
    """`path`'s sha256, once per (size, time) of the file."""
    return sha256_file(path)


_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def without_colour(text: str) -> str:
    """`text` without the terminal's colour codes Ray writes into its task tracebacks."""
    return _ANSI.sub("", text)
