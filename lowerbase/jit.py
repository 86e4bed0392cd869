"""The project's one way to compile a numba kernel (lowerbase.world.raycast_kernel,
lowerbase.navigation.kernels, ...): ``nopython``, ``nogil``, cached on disk, and compiled in
memory where no cache location is writable. Import it only from kernel modules: it imports
numba.

numba checks a cached kernel only against its own source file, so a kernel that calls one from
another module (``lean_batch.batch`` -> ``lean_kernel.period``) would keep running the old
compiled callee after that module changed. Each kernel's cache therefore lives in a directory
named by a digest of its module and of every module of its package that module imports,
directly or not (read from the import statements): ``<base>/<digest>/``, where ``<base>`` is
``NUMBA_CACHE_DIR`` when set, else ``__pycache__/numba`` at the package's root, else the user's
cache (``~/.cache/lowerbase/numba``)."""

from __future__ import annotations

import ast
import hashlib
import importlib
import os
import sys
import threading
from collections.abc import Callable, Sequence
from functools import cache
from pathlib import Path
from typing import Any, TypeVar, cast

import numba
from numba.core import config as _numba_config

F = TypeVar("F", bound=Callable[..., Any])

numba_config: Any = _numba_config  # read at runtime (CACHE_DIR), not typed by numba
#: held while numba's global CACHE_DIR is set for one kernel: two threads importing kernel
#: modules at once would otherwise restore it under each other, and numba would join its
#: subdirectory to "" (a stray ``world_<sha1>/`` in the working directory)
_CACHE_DIR_LOCK = threading.Lock()


def compiled(**options: Any) -> Callable[[F], F]:
    """A decorator: ``fn`` compiled by ``numba.njit`` with ``options`` (e.g. error_model)."""
    def wrap(fn: F) -> F:
        where = cache_dir(fn.__module__)
        with _CACHE_DIR_LOCK:
            return _njit(fn, where, options)
    return wrap


def _njit(fn: F, where: str, options: dict[str, Any]) -> F:
    """``numba.njit`` of ``fn`` with numba's cache in ``where`` (under the lock)."""
    saved = numba_config.CACHE_DIR
    numba_config.CACHE_DIR = where
    try:
        return cast(F, numba.njit(cache=True, nogil=True, **options)(fn))
    except RuntimeError:  # "cannot cache function ...: no locator available" (read-only)
        return cast(F, numba.njit(nogil=True, **options)(fn))
    finally:
        numba_config.CACHE_DIR = saved


#: every module with kernels (``lowerbase warm`` compiles them all; a test keeps the list whole)
KERNEL_MODULES = (
    "lowerbase.protocol.frame_kernel",
    "lowerbase.firmware_model.lean_frames",
    "lowerbase.firmware_model.lean_kernel",
    "lowerbase.firmware_model.lean_batch",
    "lowerbase.firmware_model.imu_kernel",
    "lowerbase.legged.kernels",
    "lowerbase.driver.ekf_kernels",
    "lowerbase.legged_driver.reply_kernel",
    "lowerbase.world.raycast_kernel",
    "lowerbase.world.scan_kernel",
    "lowerbase.world.localization.pf_kernel",
    "lowerbase.world.localization.likelihood_kernel",
    "lowerbase.navigation.kernels",
    "lowerbase.navigation.pursuit_kernels",
)


#: the kernel modules the emulated chassis (``lowerbase emulate``) compiles
CHASSIS_KERNEL_MODULES = tuple(m for m in KERNEL_MODULES if ".firmware_model." in m)
#: the kernel modules the emulated legged robot (``lowerbase emulate --robot legged``) compiles
LEGGED_KERNEL_MODULES = ("lowerbase.protocol.frame_kernel", "lowerbase.legged.kernels")


def uncached(modules: Sequence[str] = KERNEL_MODULES) -> list[str]:
    """The kernel ``modules`` with no compiled kernel in their cache yet (their first use
    compiles them: seconds to minutes each)."""
    missing = []
    for module in modules:
        importlib.import_module(module)  # its package's sources decide the cache's name
        where = cache_dir(module)
        tag = f"py{sys.version_info.major}{sys.version_info.minor}"  # numba's index: per Python
        if not where or not any(Path(where).rglob(f"*.{tag}.nbi")):
            missing.append(module)
    return missing


@cache
def cache_dir(module: str) -> str:
    """The directory ``module``'s kernels are cached in ("" when none is writable: numba then
    tries its own locations, next to the module or user-wide)."""
    digest = source_digest(module)
    for base in _bases(module):
        path = base / digest
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(path, os.W_OK):
            return str(path)
    return ""


def _bases(module: str) -> list[Path]:
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return [Path(user)]
    bases = []
    root = _package_root(module)
    if root is not None:
        bases.append(root / "__pycache__" / "numba")
    bases.append(Path.home() / ".cache" / "lowerbase" / "numba")
    return bases


@cache
def source_digest(module: str) -> str:
    """sha256 (16 hex digits) over the sources of ``module`` and of the modules of its top-level
    package it imports, transitively; the module's name when its source cannot be read."""
    files = sorted(_sources(module))
    if not files:
        return module.replace(".", "_")
    h = hashlib.sha256()
    for path in files:
        h.update(str(path.name).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _package_root(module: str) -> Path | None:
    top = sys.modules.get(module.partition(".")[0])
    files = getattr(top, "__path__", None)
    return Path(next(iter(files))) if files else None


def _module_file(name: str) -> Path | None:
    """The source file of module ``name`` (a package's __init__.py), if it is on disk."""
    root = _package_root(name)
    if root is None:
        mod = sys.modules.get(name)
        file = getattr(mod, "__file__", None)
        return Path(file) if file and name == name.partition(".")[0] else None
    rel = name.split(".")[1:]
    for candidate in (root.joinpath(*rel).with_suffix(".py") if rel else None,
                      root.joinpath(*rel, "__init__.py")):
        if candidate is not None and candidate.is_file():
            return candidate
    return None


def _sources(module: str) -> set[Path]:
    top = module.partition(".")[0]
    seen: set[Path] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        path = _module_file(name)
        if path is None or path in seen:
            continue
        seen.add(path)
        try:
            tree = ast.parse(path.read_bytes())
        except (OSError, SyntaxError, ValueError):
            continue
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                todo += [a.name for a in node.names if a.name.partition(".")[0] == top]
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(node, package)
                if base is None or base.partition(".")[0] != top:
                    continue
                todo.append(base)
                todo += [f"{base}.{a.name}" for a in node.names]  # submodules imported by name
    return seen


def _absolute(node: ast.ImportFrom, package: str) -> str | None:
    if node.level == 0:
        return node.module
    parts = package.split(".")
    if node.level - 1 > len(parts) - 1:
        return None
    head = ".".join(parts[: len(parts) - (node.level - 1)])
    return f"{head}.{node.module}" if node.module else head
