"""Codec against cantools, deframer throughput, python-can virtual bus round trip."""

from __future__ import annotations

import os
import random
import time
from collections.abc import Callable

import can

from benchmarks.common import Row, best_rate, percentile
from lowerbase.protocol.codec import default_codec
from lowerbase.protocol.framing import Deframer, Framer


def _samples() -> list[tuple[str, int, dict[str, float | int], bytes]]:
    codec = default_codec()
    rng = random.Random(1)
    out = []
    for m in codec:
        sets = list(m.variants.items()) or [(0, m.signals)]  # multiplexed: every value in turn
        for i in range(20):
            mux, signals = sets[i % len(sets)]
            values: dict[str, float | int] = {}
            for s in signals:
                if s.is_multiplexer:
                    values[s.name] = mux
                elif s.is_float:
                    values[s.name] = round(rng.uniform(-1000, 1000), 2)
                else:
                    raw = rng.randint(s.raw_min, s.raw_max)
                    values[s.name] = raw if s.kind == "identity" else raw * s.scale + s.offset
            out.append((m.name, m.frame_id, values, m.encode(values)))
    return out


def _cpu_rates(fns: dict[str, Callable[[], int]], repeat: int) -> dict[str, float]:
    """Operations per CPU second of each function: the best of ``repeat`` rounds, the
    functions taking turns (back to back), so a busy moment of a shared host hits them alike."""
    best = dict.fromkeys(fns, 0.0)
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.process_time()
            n = fn()
            best[name] = max(best[name], n / max(time.process_time() - t0, 1e-9))
    return best


def run(quick: bool = False) -> list[Row]:
    codec = default_codec()
    db = codec.database
    samples = _samples()
    rounds = 20 if quick else 100
    ours_by_id = {m.frame_id: m for m in codec}
    ref_by_id = {m.frame_id: m for m in db.messages}
    for _name, fid, values, data in samples:  # identical results before timing anything
        assert ours_by_id[fid].encode(values) == ref_by_id[fid].encode(values)
        assert ours_by_id[fid].decode(data) == ref_by_id[fid].decode(data, decode_choices=False)

    def dec_ours() -> int:
        for _ in range(rounds):
            for _, fid, _, data in samples:
                codec.decode(fid, data)
        return rounds * len(samples)

    table = codec.decoders()
    by_id = {m.frame_id: m for m in codec}
    per_message = [(by_id[fid], data) for _, fid, _, data in samples]

    def dec_message() -> int:
        for _ in range(rounds):
            for msg, data in per_message:
                msg.decode(data)
        return rounds * len(samples)

    def dec_table() -> int:
        for _ in range(rounds):
            for _, fid, _, data in samples:
                table[fid](data, True)
        return rounds * len(samples)

    def dec_ref() -> int:
        for _ in range(rounds // 5 or 1):
            for _, fid, _, data in samples:
                db.decode_message(fid, data, decode_choices=False)
        return (rounds // 5 or 1) * len(samples)

    def enc_ours() -> int:
        for _ in range(rounds):
            for name, _, values, _ in samples:
                codec.encode(name, values)
        return rounds * len(samples)

    def enc_ref() -> int:
        for _ in range(rounds // 5 or 1):
            for name, _, values, _ in samples:
                db.encode_message(name, values)
        return (rounds // 5 or 1) * len(samples)

    load = os.getloadavg()[0]
    rates = _cpu_rates({"ours": dec_ours, "ref": dec_ref, "table": dec_table,
                        "message": dec_message}, 5 if quick else 15)
    d_ours, d_ref, d_table, d_msg = (rates[k] for k in ("ours", "ref", "table", "message"))
    e_ours, e_ref = best_rate(enc_ours), best_rate(enc_ref)

    framer = Framer()
    stream = b"".join(framer.encode(fid, data) for _, fid, _, data in samples) * (
        5 if quick else 25)

    def deframe() -> int:
        d = Deframer()
        for i in range(0, len(stream), 4096):
            d.feed(stream[i : i + 4096])
        return len(stream)

    mbps = best_rate(deframe, 3) / 1e6

    a = can.Bus(interface="virtual", channel="bench-rt")
    b = can.Bus(interface="virtual", channel="bench-rt")
    rtts = []
    msg = can.Message(arbitration_id=0x20, data=bytes(6), is_extended_id=False)
    for _ in range(500 if quick else 5000):
        t0 = time.perf_counter()
        a.send(msg)
        got = b.recv(1.0)
        b.send(got)  # type: ignore[arg-type]
        a.recv(1.0)
        rtts.append((time.perf_counter() - t0) * 1e6)
    a.shutdown()
    b.shutdown()
    n = len(samples)
    return [
        Row("codec", "decode, compiled codec", d_ours, "frames/s",
            f"codec.decode(frame_id, data); {n} frames, all 21 messages; CPU time, best of "
            f"turns with cantools (load {load:.1f})"),
        Row("codec", "decode, cantools", d_ref, "frames/s", "decode_choices=False"),
        Row("codec", "decode speed-up", d_ours / d_ref, "x", "target >= 5x, identical results"),
        Row("codec", "decode speed-up, message's decode", d_msg / d_ref, "x",
            "codec.message(...).decode(data)"),
        Row("codec", "decode speed-up, ID-dispatch table", d_table / d_ref, "x",
            "codec.decoders()[frame_id](data, True): a receive loop's own dispatch"),
        Row("codec", "encode, compiled codec", e_ours, "frames/s", "strict"),
        Row("codec", "encode, cantools", e_ref, "frames/s", "strict"),
        Row("codec", "encode speed-up", e_ours / e_ref, "x", "target >= 5x, identical results"),
        Row("framing", "deframer throughput", mbps, "MB/s", "4 KiB chunks, valid frames"),
        Row("bus", "virtual bus round trip p50", percentile(rtts, 50), "us", "python-can virtual"),
        Row("bus", "virtual bus round trip p99", percentile(rtts, 99), "us", ""),
    ]
