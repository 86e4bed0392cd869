"""docs/legged-protocol.md is generated from legged.dbc and current."""

from __future__ import annotations

from pathlib import Path

from lowerbase.protocol.docs import main, render_legged
from lowerbase.protocol.legged import legged_codec
from tests.conftest import ROOT


def test_legged_protocol_doc_is_current() -> None:
    assert (ROOT / "docs" / "legged-protocol.md").read_text(encoding="utf-8") == render_legged()


def test_entry_point_writes_it(tmp_path: Path) -> None:
    out = tmp_path / "legged-protocol.md"
    assert main(["--legged", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert text == render_legged()
    for m in legged_codec():
        assert f"### {m.name} (0x{m.frame_id:03X})" in text
    assert "FF FF FF FF FF FF FF FC | enter motor mode" in text
    assert "serial framing" not in text  # the legged buses are CAN only
