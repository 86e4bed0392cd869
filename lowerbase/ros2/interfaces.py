"""Build the ROS 2 interface packages that have no wheel: woosh_msgs, lowerbase_legged_msgs,
tf2_msgs and nav2_msgs (its two actions), with the ROS 2 wheels' own rosidl generators, CMake
configs and headers, into ``build/ros2/<hash>/install`` (the hash of the definitions and of this
builder), once.

Runs with the ROS 2 venv's Python (``make ros2``; ``scripts/ros2-env.sh``)::

    .venv-ros2/bin/python -m lowerbase.ros2.interfaces

The ROS 1 definitions (woosh_msgs, lowerbase_legged_msgs) are built as they are, with the names
ROS 1 gives them: ``Header`` is ``std_msgs/Header`` (ROS 2's has no ``seq``), ``time`` and
``duration`` are builtin_interfaces', and camelCase field names (woosh_msgs' ``batteryPercentage``)
and constant names (``manualMode``) are kept, although rosidl's .msg parser asks for snake_case
and UPPER_CASE: the .msg files are turned into .idl here with those two checks relaxed, and the
.idl files are what rosidl_generate_interfaces builds.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from dataclasses import dataclass
from pathlib import Path

from lowerbase.errors import LowerbaseError

#: bump when the way packages are built changes (it is part of the cache key)
BUILDER_VERSION = "2"

HERE = Path(__file__).resolve().parent
LOWERBASE = HERE.parent
REPO = LOWERBASE.parent


@dataclass(frozen=True)
class InterfacePackage:
    name: str
    source: Path
    ros1: bool  # ROS 1 definitions: Header, time and duration are translated
    license: str


PACKAGES = (
    InterfacePackage("tf2_msgs", HERE / "msg" / "tf2_msgs", False, "BSD-3-Clause"),
    InterfacePackage("nav2_msgs", HERE / "msg" / "nav2_msgs", False, "Apache-2.0"),
    InterfacePackage("woosh_msgs", LOWERBASE / "driver" / "msg" / "woosh_msgs", True,
                     "Apache-2.0"),
    InterfacePackage("lowerbase_legged_msgs",
                     LOWERBASE / "legged" / "msg" / "lowerbase_legged_msgs", True, "Apache-2.0"),
    InterfacePackage("lowerbase_sim_msgs",
                     LOWERBASE / "robot" / "msg" / "lowerbase_sim_msgs", True, "Apache-2.0"),
)

KINDS = ("msg", "srv", "action")
#: what rclpy needs, in rosidl_core_generators' order: the C code, its two typesupports (Fast
#: DDS's and introspection) and the Python bindings. rosidl_default_generators would also build
#: the C++ code and its three typesupports, about half of the build, which rclpy never loads.
GENERATORS = ("rosidl_cmake", "rosidl_typesupport_c", "rosidl_typesupport_fastrtps_c",
              "rosidl_typesupport_introspection_c", "rosidl_generator_c",
              "rosidl_generator_py", "rosidl_generator_type_description")
#: the wheels' CMake exports name the Python of the machine that built them
WHEEL_BUILD_PYTHON = "/opt/python/cp311-cp311"
#: rosidl's .msg parser wants snake_case field names and UPPER_CASE constants; ROS 1 messages
#: have camelCase ones of both (woosh_msgs/Battery's ``batteryPercentage``, ``manualMode``)
RELAXED_NAME = r"^[A-Za-z][A-Za-z0-9_]*$"


class Ros2BuildError(LowerbaseError):
    """The ROS 2 interface packages could not be built."""


def definition_files(pkg: InterfacePackage) -> list[Path]:
    """The package's .msg/.srv/.action files, relative to its source, sorted."""
    if pkg.ros1:
        files = [p for p in pkg.source.iterdir() if p.suffix[1:] in KINDS]
        return sorted(p.relative_to(pkg.source) for p in files)
    return sorted(p.relative_to(pkg.source) for kind in KINDS
                  for p in (pkg.source / kind).glob(f"*.{kind}"))


def definitions_hash() -> str:
    """A hash of every definition and of :data:`BUILDER_VERSION`: the cache key."""
    h = hashlib.sha256()
    h.update(BUILDER_VERSION.encode())
    for pkg in PACKAGES:
        for rel in definition_files(pkg):
            h.update(f"{pkg.name}/{rel.as_posix()}\0".encode())
            h.update((pkg.source / rel).read_bytes())
    return h.hexdigest()[:16]


def cache_dir(root: Path | None = None) -> Path:
    return (root or REPO / "build" / "ros2") / definitions_hash()


_ROS1_TYPES = {"Header": "std_msgs/Header", "time": "builtin_interfaces/Time",
               "duration": "builtin_interfaces/Duration"}


def translate_ros1(text: str) -> str:
    """A ROS 1 definition as ROS 2 reads it: Header, time and duration renamed."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^(\s*)(\w+)((?:\[\d*\])?\s+\w.*)$", line)
        if m and m.group(2) in _ROS1_TYPES:
            line = f"{m.group(1)}{_ROS1_TYPES[m.group(2)]}{m.group(3)}"
        out.append(line)
    return "\n".join(out) + "\n"


def dependencies(texts: list[str], own: str) -> list[str]:
    """The packages named by ``pkg/Type`` in the definitions."""
    deps = set()
    for text in texts:
        for line in text.splitlines():
            m = re.match(r"^\s*([a-z][a-z0-9_]*)/\w+", line)
            if m and m.group(1) != own:
                deps.add(m.group(1))
    return sorted(deps)


def prepare_source(pkg: InterfacePackage, dest: Path) -> None:
    """Write the package (definitions as .idl, package.xml, CMakeLists.txt) under ``dest``."""
    from rosidl_adapter import parser as adapter_parser
    from rosidl_adapter.action import convert_action_to_idl
    from rosidl_adapter.msg import convert_msg_to_idl
    from rosidl_adapter.srv import convert_srv_to_idl

    adapter_parser.VALID_FIELD_NAME_PATTERN = re.compile(RELAXED_NAME)
    adapter_parser.VALID_CONSTANT_NAME_PATTERN = re.compile(RELAXED_NAME)
    convert = {"msg": convert_msg_to_idl, "srv": convert_srv_to_idl,
               "action": convert_action_to_idl}
    defs = dest / "definitions"
    texts, idls = [], []
    for rel in definition_files(pkg):
        kind = rel.suffix[1:]
        text = (pkg.source / rel).read_text(encoding="utf-8")
        if pkg.ros1:
            text = translate_ros1(text)
        texts.append(text)
        target = defs / kind / rel.name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
        out_dir = dest / kind
        out_dir.mkdir(parents=True, exist_ok=True)
        with contextlib.redirect_stdout(io.StringIO()):  # "Reading input file: ..."
            idl = convert[kind](defs, pkg.name, Path(kind) / rel.name, out_dir)
        idls.append(idl.relative_to(dest).as_posix())
    deps = dependencies(texts, pkg.name)
    has_action = any(i.startswith("action/") for i in idls)
    if has_action:
        deps = sorted(set(deps) | {"action_msgs", "builtin_interfaces",
                                   "unique_identifier_msgs"})
    dep_xml = "\n".join(f"  <depend>{d}</depend>" for d in deps)
    (dest / "package.xml").write_text(f"""<?xml version="1.0"?>
<package format="3">
  <name>{pkg.name}</name>
  <version>0.0.0</version>
  <description>{pkg.name}, built by lowerbase.ros2.interfaces</description>
  <maintainer email="lowerbase@example.com">lowerbase</maintainer>
  <license>{pkg.license}</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{dep_xml}
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
""", encoding="utf-8")
    finds = "\n".join(f"find_package({d} REQUIRED)" for d in deps)
    generators = "\n".join(f"find_package({g} REQUIRED)" for g in GENERATORS)
    files = " ".join(f'"{i}"' for i in idls)
    (dest / "CMakeLists.txt").write_text(f"""cmake_minimum_required(VERSION 3.20)
project({pkg.name})
find_package(ament_cmake REQUIRED)
{generators}
{finds}
# the dependencies' configs register the C++ generators again: rclpy never loads them
list(FILTER AMENT_EXTENSIONS_rosidl_generate_idl_interfaces EXCLUDE REGEX "_cpp:")
rosidl_generate_interfaces(${{PROJECT_NAME}} {files} DEPENDENCIES {" ".join(deps)})
ament_export_dependencies(rosidl_default_runtime)
ament_package()
""", encoding="utf-8")


def fix_wheel_cmake(prefix: Path) -> int:
    """Point the wheels' CMake exports at this venv's Python headers and numpy; returns how
    many files were rewritten (0 the second time)."""
    import numpy

    python_include = sysconfig.get_paths()["include"]
    numpy_include = numpy.get_include()
    old_numpy = f"{WHEEL_BUILD_PYTHON}/lib/python3.11/site-packages/numpy/_core/include"
    old_python = f"{WHEEL_BUILD_PYTHON}/include/python3.11"
    count = 0
    for path in (prefix / "share").rglob("*.cmake"):
        text = path.read_text(encoding="utf-8", errors="surrogateescape")
        if WHEEL_BUILD_PYTHON not in text:
            continue
        text = text.replace(old_numpy, numpy_include).replace(old_python, python_include)
        path.write_text(text, encoding="utf-8", errors="surrogateescape")
        count += 1
    return count


PTH_NAME = "lowerbase_ros2_interfaces.pth"


def link_into_venv(install: Path) -> Path:
    """Put the built packages' Python code on this venv's path (a .pth file, so that no
    PYTHONPATH leaks into ROS 1 processes, which have woosh_msgs of their own)."""
    sites = sorted(install.glob("lib/python3*/site-packages"))
    if not sites:
        raise Ros2BuildError(f"no Python packages under {install}: remove {install.parent} and "
                             "run make ros2 again")
    pth = Path(sysconfig.get_paths()["purelib"]) / PTH_NAME
    pth.write_text(f"{sites[0]}\n", encoding="utf-8")
    return pth


def env_for(venv: Path, install: Path, old: dict[str, str] | None = None) -> dict[str, str]:
    """The variables a process of the ROS 2 venv needs beside the .pth: the built packages'
    libraries (their typesupports are found on LD_LIBRARY_PATH), the ament index, loopback."""
    old = dict(os.environ) if old is None else old
    ld = [str(install / "lib")] + [p for p in old.get("LD_LIBRARY_PATH", "").split(":") if p]
    return {
        "PATH": f"{venv / 'bin'}{os.pathsep}{old.get('PATH', '')}",
        "AMENT_PREFIX_PATH": f"{install}{os.pathsep}{venv}",
        "LD_LIBRARY_PATH": ":".join(ld),
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOCALHOST_ONLY": "1",
    }


def _run(cmd: list[str], log: Path, env: dict[str, str]) -> None:
    with log.open("a") as fh:
        fh.write("$ " + " ".join(cmd) + "\n")
        fh.flush()
        rc = subprocess.call(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env)
    if rc != 0:
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-25:])
        raise Ros2BuildError(f"{tail}\n{cmd[0]} failed (exit {rc}); the whole log is {log}: "
                             "fix the cause there and run make ros2 again")


def build(root: Path | None = None, jobs: int = 2, verbose: bool = True) -> Path:
    """Build every package into ``<cache>/install`` unless it is there; returns the install."""
    cache = cache_dir(root)
    install = cache / "install"
    if (cache / ".complete").exists():
        link_into_venv(install)
        return install
    for tool in ("cmake", "ninja", "cc", "c++"):
        if shutil.which(tool) is None:
            raise Ros2BuildError(f"{tool} not found: install it (apt-get install cmake ninja-build "
                                 "g++) and run make ros2 again")
    prefix = Path(sys.prefix)
    fix_wheel_cmake(prefix)
    if cache.exists():
        shutil.rmtree(cache)
    cache.mkdir(parents=True)
    log = cache / "build.log"
    env = dict(os.environ)
    env.update({"AMENT_PREFIX_PATH": f"{install}{os.pathsep}{prefix}",
                "CMAKE_PREFIX_PATH": f"{install}{os.pathsep}{prefix}"})
    with tempfile.TemporaryDirectory(prefix="lowerbase-ros2-") as tmp:
        for pkg in PACKAGES:
            if verbose:
                print(f"ros2 interfaces: building {pkg.name}", flush=True)
            src = Path(tmp) / "src" / pkg.name
            src.mkdir(parents=True)
            prepare_source(pkg, src)
            bld = Path(tmp) / "build" / pkg.name
            _run(["cmake", "-S", str(src), "-B", str(bld), "-G", "Ninja",
                  f"-DCMAKE_INSTALL_PREFIX={install}", f"-DCMAKE_PREFIX_PATH={install};{prefix}",
                  f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF",
                  "-DCMAKE_BUILD_TYPE=Release"], log, env)
            _run(["ninja", "-C", str(bld), f"-j{jobs}", "install"], log, env)
    link_into_venv(install)
    (cache / ".complete").write_text(definitions_hash() + "\n")
    return install


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m lowerbase.ros2.interfaces",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=None,
                    help="cache root (default: build/ros2 in the repository)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--print-install", action="store_true",
                    help="print the install directory of the current definitions and exit")
    args = ap.parse_args(argv)
    if args.print_install:
        print(cache_dir(args.root) / "install")
        return 0
    try:
        install = build(args.root, args.jobs)
    except LowerbaseError as exc:
        print(exc, file=sys.stderr)
        return 1
    print(install)
    return 0


if __name__ == "__main__":
    sys.exit(main())
