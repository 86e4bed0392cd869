"""What the tools show of the multiplexed WheelFeedback: docs/protocol.md, `lowerbase decode`
and `lowerbase dbc --signals`."""

from __future__ import annotations

import io

import pytest

from lowerbase.cli import main
from lowerbase.cli.decode import _frames_from_text, decode_stream
from lowerbase.protocol.docs import render

#: left and right frames of the pre-multiplexing wire (test_codec.WHEEL_FEEDBACK_WIRE)
LEFT, RIGHT = "40e2010000020570", "41e20100f201fa79"


def test_protocol_docs_show_the_multiplexed_layout() -> None:
    text = render()
    section = text[text.index("### WheelFeedback"):text.index("### MotionState")]
    assert "Multiplexed: Wheel (M) selects the signals of each frame; Wheel = 0 (Left): " \
        "LeftCount, LeftVelocity, LeftCurrent, LeftDriverStatus; Wheel = 1 (Right): " \
        "RightCount," in section
    rows = [line.split(" | ")[0].lstrip("| ") for line in section.splitlines()
            if line.startswith("| ") and " .. " in line]
    assert rows == ["Wheel (M)", "LeftCount (m0)", "LeftVelocity (m0)", "LeftCurrent (m0)",
                    "LeftDriverStatus (m0)", "RightCount (m1)", "RightVelocity (m1)",
                    "RightCurrent (m1)", "RightDriverStatus (m1)", "Counter"]
    other = text[text.index("### MotionState"):text.index("### Odometer")]
    assert "Multiplexed" not in other and "| Linear | " in other


def test_decode_prints_each_wheel_with_its_own_signals() -> None:
    text = f"(1.0) vcan0 100#{LEFT}\n(1.0) vcan0 100#{RIGHT}\n"
    out = io.StringIO()
    counts = decode_stream(_frames_from_text(io.StringIO(text)), raw=False, only=None, out=out)
    assert counts["decoded"] == 2 and counts["malformed"] == 0
    left, right = out.getvalue().splitlines()
    assert left.endswith("Wheel=Left LeftCount=123456 pulses LeftVelocity=0.512 m/s "
                         "LeftCurrent=1.25 A LeftDriverStatus=0 Counter=7")
    assert right.endswith("Wheel=Right RightCount=123457 pulses RightVelocity=0.498 m/s "
                          "RightCurrent=-1.50 A RightDriverStatus=4 Counter=7")  # 0.25 A steps


def test_dbc_signals_marks_the_multiplexer_and_its_values(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc", "--signals"]) == 0
    lines = capsys.readouterr().out.splitlines()
    start = next(i for i, line in enumerate(lines) if "WheelFeedback" in line)
    rows = [line.split()[:2] for line in lines[start + 1:start + 11]]
    assert rows[:3] == [["Wheel", "M"], ["LeftCount", "m0"], ["LeftVelocity", "m0"]]
    assert rows[5] == ["RightCount", "m1"] and rows[9][0] == "Counter"
    assert rows[9][1] == "60|4"  # in every frame: no marker
