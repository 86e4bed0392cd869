"""lowerbase.jit: a cached kernel is recompiled when a module it calls into changed.

numba checks a cached kernel only against its own file; without the digest directory the
second process below would still run the old ``dep.f`` (and print 11)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

from lowerbase import jit

ROOT = Path(__file__).resolve().parents[1]

DEP = """from lowerbase.jit import compiled

@compiled()
def f():
    return {value}
"""

MAIN = """from lowerbase.jit import compiled
from pkgx.dep import f

@compiled()
def g():
    return f() + 10
"""


def _run(tmp_path: Path) -> str:
    env = {"PYTHONPATH": f"{ROOT}:{tmp_path}", "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "HOME": str(tmp_path), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", "from pkgx.main import g; print(g())"],
                         env=env, capture_output=True, text=True, timeout=300, check=True)
    return out.stdout.strip()


def test_a_changed_callee_module_recompiles_its_caller(tmp_path: Path) -> None:
    pkg = tmp_path / "pkgx"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "main.py").write_text(MAIN)
    (pkg / "dep.py").write_text(DEP.format(value=1))
    assert _run(tmp_path) == "11"
    assert _run(tmp_path) == "11"  # from the cache
    (pkg / "dep.py").write_text(DEP.format(value=2))  # main.py untouched
    assert _run(tmp_path) == "12"
    caches = sorted(p.name for p in (tmp_path / "cache").iterdir())
    assert len(caches) == 4  # dep 1, main over dep 1, dep 2, main over dep 2


def test_the_digest_follows_imports_within_the_package() -> None:
    lean = jit._sources("lowerbase.firmware_model.lean_batch")
    names = {p.name for p in lean}
    assert {"lean_batch.py", "lean_kernel.py", "lean_frames.py", "lean_bits.py",
            "jit.py"} <= names
    assert "raycast_kernel.py" not in names
    assert jit.source_digest("lowerbase.firmware_model.lean_batch") != jit.source_digest(
        "lowerbase.firmware_model.lean_kernel")


def test_kernels_defined_in_two_threads_at_once_each_see_their_own_cache_dir(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # numba reads the global CACHE_DIR twice while it defines a cached kernel; a second thread
    # restoring it in between made numba cache under "" (a stray directory in the cwd)
    import threading

    seen: dict[str, object] = {}
    b_inside, a_done = threading.Event(), threading.Event()
    monkeypatch.setattr(jit, "cache_dir", lambda module: f"/cache/{module}")

    def njit(**options: object) -> object:
        def define(fn: object) -> object:
            name = getattr(fn, "__name__", "")
            if name == "a":
                b = threading.Thread(target=lambda: jit.compiled()(kernel_b))
                b.start()
                seen["b_got_in"] = b_inside.wait(0.3)  # the lock keeps it out
                seen["thread"] = b
            else:
                b_inside.set()
                a_done.wait(10.0)
            seen[name] = jit.numba_config.CACHE_DIR  # as numba's locator reads it
            return fn
        return define

    def a() -> None: ...

    def kernel_b() -> None: ...

    monkeypatch.setattr(jit.numba, "njit", njit)
    jit.compiled()(a)
    a_done.set()
    thread = seen["thread"]
    assert isinstance(thread, threading.Thread)
    thread.join(10.0)
    assert seen["a"] == f"/cache/{__name__}" and seen["kernel_b"] == f"/cache/{__name__}"
    assert seen["b_got_in"] is False
