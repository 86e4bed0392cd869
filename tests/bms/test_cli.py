"""``lowerbase bms``: options, one-line errors, and a clean Ctrl-C."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from lowerbase.cli import build_parser, main
from tests.bms import free_port

ROOT = Path(__file__).resolve().parents[2]


def test_options() -> None:
    args = build_parser().parse_args(
        ["bms", "--tcp", "127.0.0.1:1502", "--rtu", "pty:/tmp/x", "--unit", "3", "--soc", "40",
         "--charger", "--speed", "60", "--idle-timeout", "2.5"]
    )
    assert args.command == "bms" and args.unit == 3 and args.charger == "auto"
    assert args.idle_timeout == 2.5
    assert args.rtu == "pty:/tmp/x" and args.speed == 60.0 and callable(args.func)
    args = build_parser().parse_args(["bms"])
    assert args.tcp == "127.0.0.1:5020" and args.unit == 1 and args.speed == 1.0
    assert args.idle_timeout == 60.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["bms", "--tcp", "127.0.0.1:99999"], "port must be 0-65535"),
        (["bms", "--tcp", "nonexistent.invalid:5020"], "cannot listen"),
        (["bms", "--rtu", "/nonexistent/tty", "--no-tcp"], "cannot open serial port"),
        (["bms", "--soc", "120"], "--soc"),
        (["bms", "--idle-timeout", "-1"], "--idle-timeout"),
        (["bms", "--profile", "/nonexistent.toml"], "cannot read profile"),
    ],
)
def test_bad_options_print_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lowerbase bms: error:") and message in err[0]


@pytest.mark.process
def test_ctrl_c_exits_zero(tmp_path: Path) -> None:
    port = free_port()
    link = tmp_path / "bms-tty"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "lowerbase", "bms", "--tcp", f"127.0.0.1:{port}",
         "--rtu", f"pty:{link}", "--charger", "--soc", "30", "--idle-timeout", "0.5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("Ctrl-C"):
                break
        text = "".join(lines)
        assert f"Modbus TCP listening on 127.0.0.1:{port}" in text
        assert str(link) in text and link.is_symlink()
        from lowerbase.bms.link import ModbusRtuBmsLink, ModbusTcpBmsLink

        with ModbusTcpBmsLink("127.0.0.1", port, timeout=2.0) as tcp:
            snap = tcp.poll()
        assert snap is not None and snap.charge_mode == 1 and 29 < snap.soc < 31
        with ModbusRtuBmsLink(str(link), timeout=2.0) as rtu:
            assert rtu.poll() is not None
        with socket.create_connection(("127.0.0.1", port), timeout=10.0) as idle:
            assert idle.recv(1) == b""  # closed by the BMS after 0.5 s of silence
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
        assert not link.exists() and not link.is_symlink()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


@pytest.mark.process
def test_sigterm_exits_zero() -> None:
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "lowerbase", "bms", "--tcp", f"127.0.0.1:{port}"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("Ctrl-C"):
                break
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
