"""Every mbpoll command of docs/bms-modbus.md, run against the device on loopback / a pty.

A read must print exactly the device's registers, a write must change them, and a line whose
comment says "refused: <mbpoll's error>" must fail with that error and change nothing.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from lowerbase.bms.device import BmsDevice, BmsServer
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.ptybridge import PtyBridge
from lowerbase.bms.registers import HOLDING_BASE, INPUT_BASE
from tests.bms import free_port

DOC = Path(__file__).resolve().parents[2] / "docs" / "bms-modbus.md"
DOC_PORT, DOC_TTY = "5020", "/tmp/lowerbase-bms"
ERRORS = ("Illegal function", "Illegal data address", "Illegal data value")
FLAGS = {"-0", "-1", "-B", "-R", "-F", "-q", "-u", "-W", "-v"}  # mbpoll options without a value


def doc_commands() -> list[tuple[str, str]]:
    """(command, comment) of every line of a code block that starts with mbpoll."""
    commands, in_block = [], False
    for line in DOC.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_block = not in_block
        elif in_block and line.startswith("mbpoll "):
            command, _, comment = line.partition("#")
            commands.append((command.strip(), comment.strip()))
    return commands


def test_the_doc_shows_reads_writes_refusals_and_rtu() -> None:
    commands = doc_commands()
    assert len(commands) >= 5
    assert any("-m rtu" in c for c, _ in commands)
    assert any(comment.startswith("refused:") for _, comment in commands)


def parse(argv: list[str]) -> tuple[dict[str, str], list[str]]:
    options: dict[str, str] = {}
    positional: list[str] = []
    args = iter(argv[1:])
    for arg in args:
        if arg in FLAGS:
            options[arg] = ""
        elif arg.startswith("-"):
            options[arg] = next(args)
        else:
            positional.append(arg)
    return options, positional


@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[BmsServer, int, Path]]:
    device = BmsDevice(BatteryPack(soc=72.0), unit=1)
    device.step(20.0, 18.0)  # discharging: a negative current register too
    link = tmp_path / "lowerbase-bms"
    with PtyBridge(link) as bridge:
        server = BmsServer(device, tcp=("127.0.0.1", free_port()), rtu=bridge.a_path)
        server.start()
        try:
            assert server.tcp_address is not None
            yield server, server.tcp_address[1], link
        finally:
            server.stop()


@pytest.mark.skipif(
    shutil.which("mbpoll") is None,
    reason="mbpoll not on PATH (scripts/install-ros.sh installs it; apt-get install mbpoll)",
)
@pytest.mark.parametrize(("command", "comment"), doc_commands())
def test_doc_command(served: tuple[BmsServer, int, Path], command: str, comment: str) -> None:
    server, port, link = served
    device = server.device
    argv = shlex.split(command)
    options, (target, *values) = parse(argv)
    if options["-m"] == "tcp":
        assert options["-p"] == DOC_PORT and target == "127.0.0.1"
        argv[argv.index("-p") + 1] = str(port)
    else:
        assert target == DOC_TTY
        argv[argv.index(target)] = str(link)
    before = device.holding_registers()
    run = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    output = run.stdout + run.stderr
    if comment.startswith("refused:"):
        error = next(e for e in ERRORS if e.lower() in comment.lower())
        assert run.returncode != 0 and error in output
        assert device.holding_registers() == before
        return
    assert run.returncode == 0, output
    address, count = int(options["-r"]), int(options.get("-c", "1"))
    if values:
        assert f"Written {len(values)} references" in run.stdout
        assert device.holding_registers()[address - HOLDING_BASE :][: len(values)] == [
            int(v) for v in values
        ]
        return
    image, base = (
        (device.input_registers(), INPUT_BASE) if options["-t"] == "3"
        else (device.holding_registers(), HOLDING_BASE)
    )
    printed = {}
    for line in run.stdout.splitlines():
        if line.startswith("["):
            index, _, value = line.partition(":")
            printed[int(index.strip("[]"))] = int(value.split()[0])
    expected = image[address - base :][:count]
    assert len(expected) == count
    assert printed == dict(zip(range(address, address + count), expected, strict=True))
