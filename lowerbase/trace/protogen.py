"""Compile ``proto/trace.proto`` with grpcio-tools' protoc (a dev dependency).

The generated ``proto/trace_pb2.py`` (+ ``.pyi`` for mypy) is checked in, so that lowerbase needs
only the protobuf runtime; ``tests/trace/test_proto.py`` regenerates it and compares.
Run ``python -m lowerbase.trace.protogen`` after editing the .proto.
"""

from __future__ import annotations

import sys
from pathlib import Path

from lowerbase.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]  #: the import root holding lowerbase/
PROTO = Path(__file__).with_name("proto") / "trace.proto"


def compile_proto(out: Path, proto: Path = PROTO) -> list[Path]:
    """Run protoc on ``proto`` (named relative to the import root, so that the descriptor's
    file name is ``lowerbase/trace/proto/trace.proto``); the generated files under ``out``."""
    try:
        from grpc_tools import protoc
    except ImportError:
        raise ConfigError("protoc is missing: pip install -e '.[dev]' (grpcio-tools)") from None
    rel = proto.resolve().relative_to(ROOT)
    rc = protoc.main(["protoc", f"-I{ROOT}", f"--python_out={out}", f"--pyi_out={out}",
                      str(rel)])
    if rc != 0:
        raise ConfigError(f"protoc failed on {rel} (exit {rc})")
    stem = out / rel.with_suffix("")
    return [stem.with_name(stem.name + "_pb2.py"), stem.with_name(stem.name + "_pb2.pyi")]


def main() -> int:
    import shutil
    import tempfile

    with tempfile.TemporaryDirectory(prefix="lowerbase-protogen-") as tmp:
        for f in compile_proto(Path(tmp)):
            shutil.copyfile(f, PROTO.with_name(f.name))
            print(f"wrote {PROTO.with_name(f.name)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
