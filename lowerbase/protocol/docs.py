"""docs/protocol.md, generated from the DBC catalog (``lowerbase dbc --export-docs``)."""

from __future__ import annotations

from lowerbase.protocol import busload
from lowerbase.protocol.codec import Codec, MessageCodec, default_codec
from lowerbase.protocol.framing import OVERHEAD, Framer

EXAMPLE = ("MotionCommand", {"Linear": 0.5, "Angular": -0.25, "Mode": "Smoothed", "Counter": 3})


def _fmt(x: float | None) -> str:
    if x is None:
        return ""
    return f"{x:g}" if isinstance(x, float) else str(x)


def _bitrate(codec: Codec) -> int:
    """The bus bit rate the catalog declares (attribute Baudrate)."""
    dbc = codec.database.dbc
    attr = dbc.attributes.get("Baudrate") if dbc is not None else None
    return int(attr.value) if attr is not None else 500_000


def _multiplexing(m: MessageCodec) -> list[str]:
    """A multiplexed message: which signals each multiplexer value selects."""
    if m.multiplexer is None:
        return []
    mux = m.multiplexer
    sets = []
    for k, sigs in m.variants.items():
        label = f" ({mux.choices[k]})" if k in mux.choices else ""
        names = ", ".join(s.name for s in sigs if s.multiplexer_ids)
        sets.append(f"{mux.name} = {k}{label}: {names}")
    return [
        f"Multiplexed: {mux.name} (M) selects the signals of each frame; "
        + "; ".join(sets) + " (m<value> in the table). The other signals are in every frame.",
        "",
    ]


def _message_section(m: MessageCodec, serial: bool = True) -> list[str]:
    """One message's section; ``serial``: mention its size in the serial framing."""
    cycle = f"{m.cycle_time * 1000:g} ms" if m.cycle_time else "event"
    framing = f"; {m.length + OVERHEAD} bytes in the serial framing" if serial else ""
    lines = [
        f"### {m.name} (0x{m.frame_id:03X})",
        "",
        f"{m.comment}",
        "",
        f"DLC {m.length}, {cycle}, sent by {', '.join(m.senders)}{framing}.",
        "",
        *_multiplexing(m),
        "| signal | bits | type | scale | offset | range | unit | values | comment |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in m.signals:
        kind = "float32" if s.is_float else ("int" if s.is_signed else "uint") + str(s.length)
        bits = f"{s.start}..{s.start + s.length - 1}"
        if s.byte_order == "big_endian":  # Motorola: the DBC start bit is the MSB
            bits = f"msb {s.dbc_start}, Motorola"
        values = ", ".join(f"{k}={v}" for k, v in s.choices.items())
        mark = " (M)" if s.is_multiplexer else "".join(f" (m{k})" for k in s.multiplexer_ids)
        lines.append(
            f"| {s.name}{mark} | {bits} | {kind} | {_fmt(s.scale)} | {_fmt(s.offset)} | "
            f"{_fmt(s.minimum)} .. {_fmt(s.maximum)} | {s.unit} | {values} | {s.comment} |"
        )
    lines.append("")
    return lines


def _capacity(codec: Codec) -> list[str]:
    """The bus's capacity in eight-byte frames, with and without bit stuffing."""
    rate = _bitrate(codec)
    plain, worst = busload.unstuffed_bits(8), busload.worst_case_bits(8)
    mean = busload.mean_frame_bits(8)
    return [
        "",
        "## Bus capacity",
        "",
        "A classic data frame with an 11-bit ID and n data bytes is 44 + 8n bits (SOF, ID, RTR, "
        "IDE, r0, DLC, CRC 15, CRC delimiter, ACK slot and delimiter, EOF 7) plus 3 bits of "
        "interframe space. Bit stuffing inserts one bit after every five equal bits from SOF "
        "to the end of the CRC (34 + 8n bits), at most floor((34 + 8n - 1) / 4). For n = 8 at "
        f"{rate // 1000} kbit/s (`lowerbase/protocol/busload.py`):",
        "",
        "| stuffing | bits per frame | frames/s |",
        "|---|---|---|",
        f"| none | {plain} | {rate / plain:,.1f} |",
        f"| typical (mean over uniformly random IDs and data) | {mean:.2f} | {rate / mean:,.1f} |",
        f"| worst case (+{worst - plain}) | {worst} | {rate / worst:,.1f} |",
    ]


def render(codec: Codec | None = None) -> str:
    codec = codec or default_codec()
    name, values = EXAMPLE
    msg = codec.message(name)
    payload = msg.encode(values)
    frame = Framer().encode(msg.frame_id, payload)
    n = len(payload)
    parts = (
        [("SOF", 0, 2), ("LEN", 2, 1), ("ID", 3, 2), ("PAYLOAD", 5, n), ("SEQ", 5 + n, 1),
         ("CRC", 6 + n, 2)]
    )
    out = [
        "# The lowerbase wire protocol",
        "",
        "Generated from `lowerbase/protocol/chassis.dbc` by `lowerbase dbc --export-docs "
        "docs/protocol.md`; do not edit by hand (a test checks it is current).",
        "",
        f"Classic CAN 2.0A, 11-bit identifiers, {_bitrate(codec) // 1000} kbit/s, Intel "
        "(little-endian) byte order throughout. Lower identifiers carry "
        "safety and commands. Periodic frames carry a 4-bit rolling counter (+1 per frame, mod "
        "16); StatusCode needs all 64 bits for the code and relies on the SystemStatus counter "
        "sent in the same cycle.",
        "",
        "## Catalog",
        "",
        "| ID | message | DLC | cycle | sender |",
        "|---|---|---|---|---|",
    ]
    for m in codec:
        cycle = f"{m.cycle_time * 1000:g} ms" if m.cycle_time else "event"
        out.append(f"| 0x{m.frame_id:03X} | {m.name} | {m.length} | {cycle} | "
                   f"{', '.join(m.senders)} |")
    out += _capacity(codec)
    out += [
        "",
        "## Serial framing",
        "",
        "The same frames over a UART (or a pseudo-terminal): start of frame, length, ID, payload,",
        "link sequence counter, CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no",
        "final XOR) over LEN..SEQ. Multi-byte fields are little-endian. A frame is DLC + "
        f"{OVERHEAD} bytes.",
        "",
        "| offset | size | field | meaning |",
        "|---|---|---|---|",
        "| 0 | 2 | SOF | 0xAA 0x55 |",
        "| 2 | 1 | LEN | payload length 0..8 |",
        "| 3 | 2 | ID | 11-bit identifier (upper 5 bits zero) |",
        "| 5 | LEN | PAYLOAD | the CAN payload, as on the bus |",
        "| 5+LEN | 1 | SEQ | +1 per frame sent (mod 256); gaps count lost frames |",
        "| 6+LEN | 2 | CRC | over LEN..SEQ |",
        "",
        f"Example: {name} with "
        + ", ".join(f"{k}={v}" for k, v in values.items())
        + " (sequence number 0):",
        "",
        "```",
        frame.hex(" ").upper(),
        "```",
        "",
        "| bytes | field | value |",
        "|---|---|---|",
    ]
    for field, offset, size in parts:
        chunk = frame[offset : offset + size]
        if field == "ID" or field == "CRC":
            meaning = f"0x{int.from_bytes(chunk, 'little'):04X}"
        elif field == "LEN":
            meaning = str(chunk[0])
        elif field == "PAYLOAD":
            meaning = ", ".join(
                f"{s.name}={values[s.name]}" for s in msg.signals
            )
        elif field == "SEQ":
            meaning = str(chunk[0])
        else:
            meaning = "start of frame"
        out.append(f"| {chunk.hex(' ').upper()} | {field} | {meaning} |")
    out += [
        "",
        "The deframer resynchronises on the next SOF after garbage, a truncated frame or a bad",
        "CRC, and counts each (garbage bytes, bad CRC, bad length, truncated, sequence gaps).",
        "",
        "## Messages",
        "",
    ]
    for m in codec:
        out += _message_section(m)
    return "\n".join(out).rstrip() + "\n"


def render_legged(codec: Codec | None = None) -> str:
    """docs/legged-protocol.md from ``legged.dbc`` (the legged robot's four buses)."""
    from lowerbase.protocol.legged import (
        COMMAND_MESSAGES,
        LEGS,
        MOTOR_IDS,
        REPLY_ID,
        Special,
        legged_codec,
        special_frame,
    )

    codec = codec or legged_codec()
    rate = _bitrate(codec)
    mean = busload.mean_frame_bits(8)
    per_leg = 2 * len(MOTOR_IDS) * 1000  # commands + replies at 1 kHz
    leg_ids = {*COMMAND_MESSAGES, REPLY_ID}
    out = [
        "# The legged robot's wire protocol",
        "",
        "Generated from `lowerbase/protocol/legged.dbc` by `python -m lowerbase.protocol.docs "
        "--legged docs/legged-protocol.md`; do not edit by hand (a test checks it is current). "
        "The lower computer that speaks it: docs/legged.md.",
        "",
        f"Four classic CAN 2.0A buses at {rate // 1000} kbit/s, one per leg: "
        + ", ".join(f"bus {k} {leg}" for k, leg in enumerate(LEGS))
        + ". On each leg bus the " + ", ".join(MOTOR_IDS) + " actuators have CAN IDs "
        + ", ".join(str(i) for i in MOTOR_IDS.values())
        + f" and answer on ID {REPLY_ID} with their ID in byte 0. The actuator frames are the "
        "MIT mini-cheetah motor protocol, big-endian (Motorola); the body frames travel on bus "
        "0 only and are little-endian (Intel). Periodic body frames carry a 4-bit rolling "
        "counter (+1 per frame, mod 16).",
        "",
        "## Catalog",
        "",
        "| ID | message | DLC | cycle | sender | buses |",
        "|---|---|---|---|---|---|",
    ]
    for m in codec:
        cycle = f"{m.cycle_time * 1000:g} ms" if m.cycle_time else "event"
        buses = "every leg bus" if m.frame_id in leg_ids else "bus 0"
        out.append(f"| 0x{m.frame_id:03X} | {m.name} | {m.length} | {cycle} | "
                   f"{', '.join(m.senders)} | {buses} |")
    out += [
        "",
        "## Special frames",
        "",
        "Eight-byte payloads on an actuator's command ID that no DBC signal expresses; a "
        "receiver tests for them before decoding (`lowerbase.protocol.legged.parse_special`). "
        "The actuator answers each with a MotorReply.",
        "",
        "| payload | command |",
        "|---|---|",
        *(f"| {special_frame(s).hex(' ').upper()} | {s.name.lower().replace('_', ' ')} |"
          for s in Special),
        "",
        "## Bus load",
        "",
        f"Each leg bus carries {len(MOTOR_IDS)} commands and {len(MOTOR_IDS)} replies per "
        f"millisecond: {per_leg:,} eight-byte frames/s, {per_leg * mean / rate:.0%} of "
        f"{rate // 1000} kbit/s with typical bit stuffing ({mean:.2f} bits per frame, "
        "`lowerbase/protocol/busload.py`); bus 0 adds the body frames.",
        "",
        "## Messages",
        "",
    ]
    for m in codec:
        out += _message_section(m, serial=False)
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m lowerbase.protocol.docs [--legged] FILE``: write the generated document
    (chassis.dbc's docs/protocol.md, or with --legged legged.dbc's docs/legged-protocol.md)."""
    import argparse

    from lowerbase.files import write_atomic

    p = argparse.ArgumentParser(prog="python -m lowerbase.protocol.docs")
    p.add_argument("--legged", action="store_true", help="legged.dbc instead of chassis.dbc")
    p.add_argument("file")
    args = p.parse_args(argv)
    write_atomic(args.file, render_legged() if args.legged else render())
    print(f"wrote {args.file}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
