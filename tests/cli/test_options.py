"""Command-line options refused with one clear line: --bus-kwargs, --duration, --fault times."""

from __future__ import annotations

from pathlib import Path

import pytest

from lowerbase.cli import main
from lowerbase.errors import ConfigError
from lowerbase.transport.options import check_bus_kwargs, known_keys
from lowerbase.transport.serial_bus import SerialFrameBus


def _one_error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run ``lowerbase argv``; it must fail with exactly one line on stderr."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors: usage + one error line
        code = int(exc.code or 0)
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert "Traceback" not in "\n".join(err)
    lines = [line for line in err if "error:" in line]
    assert len(lines) == 1, err
    return lines[0]


def test_bus_kwargs_value_of_the_wrong_type_is_one_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", "port=notaport"])
    assert "port=notaport" in line and "integer" in line


def test_misspelt_bus_kwargs_key_is_refused_with_did_you_mean(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", "porto=43114"])
    assert "udp_multicast has no option 'porto'" in line
    assert "did you mean 'port'?" in line


def test_python_can_range_checks_are_one_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", "port=70000"])
    assert "1-65535" in line


@pytest.mark.parametrize("port", ["0", "70000", "-1"])
def test_a_port_out_of_range_says_the_range_it_wants(
        port: str, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", f"port={port}"])
    assert f"port={port}" in line and "must be 1-65535" in line and "0-65535" not in line


@pytest.mark.parametrize("argv", [["port=43114", "port=43115"],
                                  ["port=43114", "--bus-kwargs", "port=43115"]])
def test_a_bus_kwargs_key_given_twice_is_refused(
        argv: list[str], capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", *argv])
    assert "port given twice" in line


def test_can_filters_says_the_expected_format() -> None:
    with pytest.raises(ConfigError, match=r"expected hex ID:MASK pairs.*can_filters=100:7FF"):
        check_bus_kwargs("udp_multicast", {"can_filters": "abc"})
    assert check_bus_kwargs("udp_multicast", {"can_filters": "100:7FF,200~7F0"}) == {
        "can_filters": [{"can_id": 0x100, "can_mask": 0x7FF},
                        {"can_id": 0x200 | 0x20000000, "can_mask": 0x7F0}]}


def test_can_filters_from_the_command_line_are_one_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    line = _one_error_line(capsys, ["record", str(tmp_path / "r.log"), "--duration", "0.1",
                                    "--bus-kwargs", "can_filters=abc"])
    assert "expected hex ID:MASK" in line and "string indices" not in line


def test_known_keys_come_from_the_constructor_and_the_kwargs_it_reads() -> None:
    from can.interfaces.slcan import slcanBus
    from can.interfaces.udp_multicast import UdpMulticastBus

    assert {"port", "hop_limit", "receive_own_messages"} <= known_keys(UdpMulticastBus)
    assert "btr" in known_keys(slcanBus)  # read as kwargs["btr"], not a named parameter
    assert "baudrate" in known_keys(SerialFrameBus)
    assert "porto" not in known_keys(UdpMulticastBus)


def test_values_get_the_declared_type() -> None:
    got = check_bus_kwargs("udp_multicast", {"port": 43114, "hop_limit": 0,
                                             "receive_own_messages": True})
    assert got == {"port": 43114, "hop_limit": 0, "receive_own_messages": True}
    assert check_bus_kwargs("virtual", {"rx_queue_size": 5}) == {"rx_queue_size": 5}
    with pytest.raises(ConfigError, match="true or false"):
        check_bus_kwargs("udp_multicast", {"receive_own_messages": 1})
    with pytest.raises(ConfigError, match="did you mean 'hop_limit'"):
        check_bus_kwargs("udp_multicast", {"hop_limt": 0})


def test_an_interface_that_cannot_be_imported_is_not_checked_here() -> None:
    # opening the bus reports the missing vendor library; nothing to check against
    assert check_bus_kwargs("no-such-interface", {"x": 1}) == {"x": 1}


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "soon"])
@pytest.mark.parametrize("command", ["record", "emulate"])
def test_duration_must_be_positive_seconds(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                           command: str, value: str) -> None:
    argv = [command, *([str(tmp_path / "r.log")] if command == "record" else []),
            "--duration", value, "-i", "virtual", "-c", "options-test"]
    line = _one_error_line(capsys, argv)
    assert "--duration" in line and repr(value) in line


@pytest.mark.parametrize(("spec", "what"), [
    ("stall:left@abc", "start time @T"),
    ("stall:left@1.2.3", "start time @T"),
    ("stall:left@5+x", "duration +D"),
])
def test_fault_time_errors_name_the_time(capsys: pytest.CaptureFixture[str],
                                         spec: str, what: str) -> None:
    line = _one_error_line(capsys, ["emulate", "--fault", spec, "--simulated",
                                    "--duration", "0.1", "-i", "virtual", "-c", "options-test"])
    assert what in line and "unknown fault" not in line
