"""The BMS's readings pinned bit for bit: a pack driven through every protection (trip, delay,
release), CC-CV charging to termination, cold charging, substeps and threshold writes, with
the pack state, the snapshot, the input registers, the decoded poll, the Bms* frames and the
MCU's status bits after every step hashed (float reprs are exact). Recorded before the pack
step and the register path were made cheaper; any change of a draw, an operation or its order
changes the hash."""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Iterator

from lowerbase.bms.adapter import McuBmsAdapter
from lowerbase.bms.config import BatteryConfig, ProtectionLimit, default_battery_config
from lowerbase.bms.device import BmsDevice
from lowerbase.bms.frames import snapshot_to_frames
from lowerbase.bms.pack import BatteryPack
from lowerbase.bms.registers import decode_snapshot, encode_snapshot
from lowerbase.bms.snapshot import BmsSnapshot
from lowerbase.bms.status import BmsStatus, ChargeMode

#: SHA-256 of the trace of each pack below, recorded with the code before the fast paths
PINNED = {
    "LFP": "02d511ebdbd2ee066b32ceb04e50176cddb1db39d1d0dc6e0ac440393ff2033e",
    "NMC": "1b9a34b7dc163c3fab6c067ae51a0450e3b92f842a472d40a89c6d4844473a7d",
}


def _configs() -> dict[str, BatteryConfig]:
    lfp = dataclasses.replace(default_battery_config("LFP"), thermal_mass_j_per_k=600.0,
                              charge_current_a=30.0, cold_charge_current_a=20.0)
    nmc = dataclasses.replace(default_battery_config("NMC"), thermal_mass_j_per_k=900.0,
                              capacity_ah=20.5, charge_cycles=7, submodule=3,
                              charge_current_a=25.0)
    return {"LFP": lfp, "NMC": nmc}


def _drive(pack: BatteryPack, adapter: McuBmsAdapter) -> Iterator[tuple[float, float]]:
    """(dt, load) steps; changes the charger and the thresholds between them."""
    for _ in range(60):  # cold: discharge and charge under-temperature trip
        yield 0.1, 5.0
    for _ in range(400):  # warms up through the load: they release
        yield 0.5, 40.0
    for _ in range(40):  # 2.5 C: discharge over-current trips after 1 s
        yield 0.1, 100.0
    for _ in range(50):  # released after 32 s
        yield 1.0, 3.0
    for _ in range(120):  # hot: over-temperature (LFP; NMC: over-current)
        yield 2.5, 75.0
    for _ in range(300):  # down to cell under-voltage, substeps of a long dt
        yield 7.3, 30.0
    adapter.connect_charger(ChargeMode.AUTO)
    for _ in range(900):  # CC-CV to termination (LFP; NMC: charge over-current)
        yield 9.0, 2.0
    adapter.disconnect_charger()
    for _ in range(60):  # 18 % down
        yield 10.0, 30.0
    p, cv = pack.config.protection, pack.config.charge_voltage_per_cell_v
    pack.set_protection(dataclasses.replace(p, charge_oc=ProtectionLimit(5.0, 2.0, 0.32, 2.0)))
    adapter.connect_charger(ChargeMode.MANUAL)  # charge over-current, released at 0 A
    for _ in range(60):
        yield 0.1, 0.0
    pack.set_protection(dataclasses.replace(p, cell_ov=ProtectionLimit(cv + 0.001, cv - 0.2)))
    for _ in range(400):  # cell over-voltage near full
        yield 10.0, 0.0
    adapter.disconnect_charger()
    for _ in range(100):
        yield 0.005, 12.0
    yield 0.0, 1.0


def trace(name: str, config: BatteryConfig) -> tuple[str, BmsStatus]:
    soc, temp = (60.0, -25.0) if name == "LFP" else (45.0, -22.0)
    pack = BatteryPack(config, soc=soc, temperature_c=temp)
    adapter = McuBmsAdapter(BmsDevice(pack, unit=2))
    h = hashlib.sha256()
    seen = BmsStatus.NONE
    for dt, load in _drive(pack, adapter):
        adapter.step(dt, load)
        snap = adapter.device.snapshot()  # type: ignore[union-attr]
        words = encode_snapshot(snap)
        polled = adapter.poll()
        assert polled == decode_snapshot(words)
        seen |= pack.status
        h.update(repr((pack.time_s, pack.current, pack.temperature, pack.charge_ah, pack.soc,
                       int(pack.status), int(pack.switches), snap, words, polled,
                       snapshot_to_frames(polled, {"BmsPack": 3}),
                       adapter.frame("BmsCell", polled), int(adapter.status_bits(polled)),
                       )).encode())
    return h.hexdigest(), seen


def test_bms_trace_is_pinned() -> None:
    for name, config in _configs().items():
        digest, _ = trace(name, config)
        assert (name, digest) == (name, PINNED[name])


def test_the_trace_covers_every_protection() -> None:
    seen = BmsStatus.NONE
    for name, config in _configs().items():
        seen |= trace(name, config)[1]
    assert seen & 0xFF == 0xFF, BmsStatus(0xFF & ~seen)
    assert seen & BmsStatus.FULLY_CHARGED and seen & BmsStatus.SOC_LOW


def test_packs_with_other_thresholds_stepped_in_turn() -> None:
    """The protections' trip points are kept for the last config only: two packs with
    different thresholds, stepped in turn, each read as when stepped alone."""
    base = default_battery_config("LFP")
    low = dataclasses.replace(base.protection, discharge_oc=ProtectionLimit(20.0, 10.0, 0.5, 3.0))
    configs = (base, dataclasses.replace(base, protection=low))

    def run(packs: list[BatteryPack], order: list[int]) -> list[list[tuple[BmsSnapshot, int]]]:
        out: list[list[tuple[BmsSnapshot, int]]] = [[] for _ in packs]
        for step in range(200):
            for i in order:
                packs[i].step(0.1, 30.0 if step < 100 else 1.0)
                out[i].append((packs[i].snapshot(), int(packs[i].status)))
        return out

    together = run([BatteryPack(c, soc=70.0) for c in configs], [0, 1])
    alone = [run([BatteryPack(c, soc=70.0)], [0])[0] for c in configs]
    assert together == alone
    assert any(s & BmsStatus.DISCHARGE_OVER_CURRENT for _, s in together[1])
    assert not any(s & BmsStatus.DISCHARGE_OVER_CURRENT for _, s in together[0])
