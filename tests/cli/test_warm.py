"""``lowerbase warm`` (issue 22 item 30): the kernels compile during set-up (``make env``), and
a cold cache is said, not shown as a frozen "t 0.0 s"."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from lowerbase.jit import KERNEL_MODULES
from tests.conftest import ROOT


def test_every_module_with_kernels_is_warmed() -> None:
    using = set()
    for path in (ROOT / "lowerbase").rglob("*.py"):
        if path.name != "jit.py" and re.search(r"^@(_jit|compiled)\b", path.read_text(), re.M):
            using.add(".".join(path.relative_to(ROOT).with_suffix("").parts))
    assert using == set(KERNEL_MODULES)


def test_check_lists_the_kernels_a_cold_cache_lacks(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-m", "lowerbase", "warm", "--check"], env=env,
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 1, out.stderr
    for module in KERNEL_MODULES:
        assert f"{module}: not compiled yet" in out.stdout
    assert f"0 of {len(KERNEL_MODULES)} kernel modules compiled" in out.stdout


def test_make_env_warms_the_kernels() -> None:
    recipe = (ROOT / "Makefile").read_text()
    assert "-m lowerbase warm" in recipe.split("env:")[0]  # in the venv's set-up recipe


def test_emulate_says_when_its_kernels_compile_in_the_run(tmp_path: Path) -> None:
    """issue 22 item 25: a cold cache cost a simulated emulate run its factor unsaid."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    code = ("from lowerbase.cli.emulate import compile_notice; "
            "from lowerbase.jit import CHASSIS_KERNEL_MODULES as m; "
            "print(m); print(compile_notice()); print(compile_notice('legged'))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "lowerbase.firmware_model.lean_kernel" in out.stdout
    assert "lowerbase.world" not in out.stdout
    assert "compiling the chassis' numba kernels first" in out.stdout
    assert "compiling the legged robot's numba kernels first" in out.stdout
