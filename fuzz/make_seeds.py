#!/usr/bin/env python3
"""Writes the binary seed inputs of the CAN, SDO and Modbus fuzzers
(fuzz/corpus/...). Frames follow docs/hardware.md and config/remote.yaml
(drives 1-4 on bus arm_a, 5-7 and the F/T sensor, node 32, on arm_b).
Run from anywhere: python3 fuzz/make_seeds.py"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def frame(cob, data):
    """struct can_frame: can_id u32, dlc u8, 3 pad bytes, 8 data bytes."""
    data = bytes(data)
    return struct.pack("<IB3x8s", cob, len(data), data.ljust(8, b"\0"))


def rec(bus, cob, data):
    return bytes([bus & 1]) + frame(cob, data)


def write(target, name, blob):
    d = os.path.join(HERE, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(blob)


# ---- fuzz_can_frames: one cycle of a healthy arm, then faults --------------------
def tpdo(node, statusword, counts, torque):
    return struct.pack("<HiH", statusword, counts, torque & 0xFFFF)


healthy = b""
for node in range(1, 8):
    bus = 0 if node <= 4 else 1
    healthy += rec(bus, 0x180 + node, tpdo(node, 0x0237, 1000 * node, 10))
    healthy += rec(bus, 0x700 + node, [0x05])  # heartbeat: operational
ft = struct.pack("<hhhBB", 100, -50, 981, 0, 7)
healthy += rec(1, 0x180 + 32, ft)
healthy += rec(1, 0x280 + 32, struct.pack("<hhhBB", 3, -2, 1, 0, 7))
write("fuzz_can_frames", "healthy_cycle", healthy)

faults = b""
faults += rec(0, 0x080 + 3, struct.pack("<HB5x", 0x8611, 0x80))  # EMCY following error
faults += rec(0, 0x700 + 2, [0x00])  # boot-up
faults += rec(1, 0x180 + 32, struct.pack("<hhhBB", 32767, 0, 0, 0x01, 9))  # saturated Fx
faults += rec(1, 0x280 + 32, struct.pack("<hhhBB", 0, 0, 0, 0x40, 10))  # sequence mismatch, fault
faults += rec(0, 0x580 + 1, [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00])  # stray SDO
faults += rec(0, 0x20000000 | 0x004, [0] * 8)  # error frame (CAN_ERR_FLAG | bus-off)
faults += rec(0, 0x40000000 | 0x181, [])  # RTR
faults += bytes([0x80 | (5 << 1)]) + b"\x01\x02\x03\x04\x05"  # a 5-byte datagram
write("fuzz_can_frames", "faults", faults)

# ---- fuzz_sdo: responses of drive node 1 ---------------------------------------
expedited = bytes([0]) + frame(0x581, [0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00])
write("fuzz_sdo", "expedited_device_type", expedited)
name = b"SimDrive 402"
seg = bytes([1]) + frame(0x581, [0x41, 0x08, 0x10, 0x00] + list(struct.pack("<I", len(name))))
toggle = 0
for i in range(0, len(name), 7):
    part = name[i:i + 7]
    last = i + 7 >= len(name)
    cs = (toggle << 4) | ((7 - len(part)) << 1) | (1 if last else 0)
    seg += frame(0x581, [cs] + list(part))
    toggle ^= 1
write("fuzz_sdo", "segmented_device_name", seg)
write("fuzz_sdo", "download_confirm", bytes([2]) + frame(0x581, [0x60, 0x60, 0x60, 0x00, 0, 0, 0, 0]))
write("fuzz_sdo", "abort", bytes([0]) + frame(0x581, [0x80, 0x00, 0x10, 0x00, 0x00, 0x00, 0x02, 0x06]))

# ---- fuzz_modbus_registers: LST and video switch register blocks ------------------
write("fuzz_modbus_registers", "lst_running",
      bytes([0]) + struct.pack("<8H", 0x0003, 0, 1234, 200, 60, 77, 250, 0))
write("fuzz_modbus_registers", "video_status",
      bytes([1]) + struct.pack("<8H", 2, 100, 65500, 800, 4, 12, 0, 3))
