"""An emulated protocol v2 chassis on an slcan adapter, written from the vendor's field layout
(ugv_sdk `agilex_protocol_v2.h`: `MotionCommandFrame`, `SystemStateFrame`, `MotionStateFrame`,
`ControlModeConfigFrame`), not from this project's codec or its simulator: it checks what the
gateway puts on the wire against the vendor's layout.

It opens a pseudo-terminal, prints its path on the first line of stdout, answers the slcan
set-up (C, S6, O), and every 20 ms reports 0x211 (normal, standby until a 0x421 asks for CAN
command mode, 26.0 V) and 0x221 (the last motion command, while fresh). Each 0x111 whose fields
differ from the one before is printed as a JSON line: {"linear_mm_s", "angular_mrad_s",
"lateral_mm_s", "steering_mrad"}, big-endian int16 from bytes 0-1, 2-3, 4-5, 6-7. Standard
library only; ends on SIGTERM or after 60 s.

With --motion-modes it is a Ranger (`SetMotionModeFrame`, `MotionModeStateFrame`): it reports
0x291 (its mode in byte 0, byte 1 set while changing) every 20 ms, starting in dual Ackermann
(0); a 0x141 is printed as {"set_motion_mode": mode} and, standing still, changes the mode in
0.2 s; a 0x111 that is not zero while it changes is printed as {"moved_while_changing": [...]}.

With --brake it is a Hunter (`BrakeModeConfigFrame`; the Hunter 2.0 manual's 0x211 byte 6):
its parking brake starts locked (1) and is reported in 0x211 byte 6; a 0x131 is printed as
{"brake": byte 0} and sets it (0 released, 1 locked); a 0x111 with a speed while it is locked
is printed as {"moved_while_locked": [...]} and moves nothing. Without it, a 0x131 is printed
all the same (and changes nothing): a chassis without a brake should never be sent one.
"""

import json
import os
import select
import signal
import struct
import sys
import time
import tty

MOTION_COMMAND = 0x111
CONTROL_MODE_CONFIG = 0x421
SYSTEM_STATE = 0x211
MOTION_STATE = 0x221
SET_MOTION_MODE = 0x141
MOTION_MODE_STATE = 0x291
BRAKE_COMMAND = 0x131
MODE_CHANGE = 0.2
CAN_COMMAND_MODE = 0x01
COMMAND_TIMEOUT = 0.5
PERIOD = 0.02


def frame_line(can_id: int, data: bytes) -> bytes:
    return b"t%03X%d%s\r" % (can_id, len(data), data.hex().upper().encode())


def write(fd: int, data: bytes) -> None:
    try:
        os.write(fd, data)
    except (BlockingIOError, OSError):
        pass


def main() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    # Nobody may be reading yet: a full buffer drops reports rather than blocking.
    os.set_blocking(master, False)
    print(os.ttyname(slave), flush=True)
    running = [True]
    signal.signal(signal.SIGTERM, lambda *_: running.__setitem__(0, False))
    control_mode = 0
    command = (0, 0, 0, 0)
    command_at = 0.0
    printed = None
    count = 0
    modes = "--motion-modes" in sys.argv[1:]
    mode, changing_until = 0, 0.0
    has_brake = "--brake" in sys.argv[1:]
    brake = 1 if has_brake else 0
    pending = b""
    start = time.monotonic()
    next_report = start
    while running[0] and time.monotonic() - start < 60:
        timeout = max(0.0, next_report - time.monotonic())
        readable, _, _ = select.select([master], [], [], timeout)
        if readable:
            try:
                pending += os.read(master, 4096)
            except BlockingIOError:
                pass
            except OSError:
                break
            while b"\r" in pending:
                line, pending = pending.split(b"\r", 1)
                if line[:1] in (b"C", b"S", b"O"):
                    write(master, b"\r")
                    continue
                if line[:1] != b"t" or len(line) < 5:
                    continue
                can_id = int(line[1:4], 16)
                length = int(line[4:5], 16)
                data = bytes.fromhex(line[5 : 5 + 2 * length].decode())
                if can_id == CONTROL_MODE_CONFIG and data[:1] == bytes([CAN_COMMAND_MODE]):
                    control_mode = CAN_COMMAND_MODE
                elif modes and can_id == SET_MOTION_MODE and len(data) == 8:
                    print(json.dumps({"set_motion_mode": data[0]}), flush=True)
                    now = time.monotonic()
                    fresh = now - command_at <= COMMAND_TIMEOUT
                    still = not fresh or command == (0, 0, 0, 0)
                    if still and now >= changing_until and data[0] != mode:
                        mode, changing_until = data[0], now + MODE_CHANGE
                elif can_id == BRAKE_COMMAND:
                    print(json.dumps({"brake": data[0] if data else None}), flush=True)
                    if has_brake and len(data) == 8 and data[0] in (0, 1):
                        brake = data[0]
                elif can_id == MOTION_COMMAND and len(data) == 8:
                    fields = struct.unpack(">hhhh", data)
                    if brake and fields[0] != 0:
                        print(json.dumps({"moved_while_locked": fields}), flush=True)
                        fields = (0, 0, 0, fields[3])
                    if modes and time.monotonic() < changing_until and fields != (0, 0, 0, 0):
                        print(json.dumps({"moved_while_changing": fields}), flush=True)
                    if control_mode == CAN_COMMAND_MODE:
                        command, command_at = fields, time.monotonic()
                    if fields != printed:
                        printed = fields
                        names = ("linear_mm_s", "angular_mrad_s", "lateral_mm_s", "steering_mrad")
                        print(json.dumps(dict(zip(names, fields))), flush=True)
        now = time.monotonic()
        if now >= next_report:
            next_report += PERIOD
            count = (count + 1) % 256
            # vehicle_state 0 (normal), control_mode, battery_voltage (0.1 V), error_code, reserved, count
            system = struct.pack(">BBHHBB", 0, control_mode, 260, 0, brake, count)
            fresh = now - command_at <= COMMAND_TIMEOUT
            motion = struct.pack(">hhhh", *(command if fresh else (0, 0, 0, 0)))
            frames = frame_line(SYSTEM_STATE, system) + frame_line(MOTION_STATE, motion)
            if modes:
                mode_state = bytes([mode, 1 if now < changing_until else 0]) + bytes(6)
                frames += frame_line(MOTION_MODE_STATE, mode_state)
            write(master, frames)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
