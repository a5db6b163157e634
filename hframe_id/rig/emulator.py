"""An emulated rig microcontroller on a pseudo-terminal, running the ``sim`` plant.

``python -m hframe_id.rig.emulator --params models/hframe-8-table4.2.yaml`` opens a
pseudo-terminal, prints ``PORT <path>`` and then behaves like the rig's firmware
(docs/serial-protocol.md): it answers HELLO with INFO, and after START samples every period on
its own clock, streams SAMPLE frames, applies the newest COMMAND at each tick, drops the
outputs to 0 V when commands stop for the watchdog time and cuts them (latched until STOP) from
the tick after a limit switch reads closed. Its device clock is the ideal one of
a crystal (k x period); the plant is stepped exactly one period per tick.

Modes: real time (default, like hardware) or ``--lockstep`` (a test aid: after each sample it
waits up to ``min(watchdog / 2, 20 ms)`` for that sample's command before the next tick, so the
run is deterministic and equals the ``sim`` rig with the same seed, whatever the load).

Injected faults (by sample sequence): ``--corrupt-every N`` flips a payload byte of every N-th
SAMPLE frame, ``--drop-every N`` never sends every N-th, ``--stop-after N`` goes silent after N
samples (a hung device), ``--disconnect-after N`` closes the port after N samples.
"""

from __future__ import annotations

import argparse
import errno
import json
import math
import os
import select
import sys
import time
import tty
from pathlib import Path

import numpy as np

from hframe_id import __version__
from hframe_id.parameters import load_parameter_file
from hframe_id.rig import serial_protocol as sp
from hframe_id.rig.sim import SimRig


class Emulator:
    """The device side of the protocol over a file descriptor (a pty master)."""

    def __init__(self, fd: int, args: argparse.Namespace) -> None:
        self.fd = fd
        self.args = args
        self.params = load_parameter_file(args.params)
        travel = {axis: (low, high) for axis, low, high in args.travel} if args.travel else None
        self.make_plant = lambda period_s: SimRig(
            self.params, seed=args.seed, paced=False, sample_period_s=period_s, travel_m=travel
        )
        self.plant = self.make_plant(args.period_us * 1e-6)
        self.decoder = sp.Decoder()
        self.overruns = 0
        self.silent = False

    # -- io ----------------------------------------------------------------------------------------
    def send(self, frame: bytes) -> None:
        """Write one frame to the host; dropped (``overruns`` + 1) if the host is not reading."""
        if self.silent:
            return
        try:
            os.write(self.fd, frame)
        except BlockingIOError:
            self.overruns += 1  # host not reading: drop, like a device with a full USB buffer
        except OSError as err:
            if err.errno in (errno.EIO, errno.EBADF):
                raise SystemExit(0) from None
            raise

    def poll(self, timeout: float) -> list[tuple[int, bytes]]:
        """Frames the host sent within ``timeout`` [s], as (frame type, payload); [] if none."""
        readable, _, _ = select.select([self.fd], [], [], max(timeout, 0.0))
        if not readable:
            return []
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return []
        except OSError as err:
            if err.errno == errno.EIO:  # no host has the port open: wait for one
                time.sleep(min(max(timeout, 0.0), 0.01))
                return []
            raise
        return self.decoder.feed(data)

    def info(self) -> dict:
        """The INFO record: protocol version, identity, channels, sensors, travel [m]."""
        plant = self.plant.info
        s = plant.sensors
        return {
            "protocol_version": sp.PROTOCOL_VERSION,
            "serial_number": f"EMU-{plant.variant}-{self.args.seed}",
            "firmware": f"hframe-id emulator {__version__}",
            "variant": plant.variant,
            "inputs": list(plant.inputs),
            "outputs": list(plant.outputs),
            "sample_period_us": self.args.period_us,
            **s.as_metadata(),
            "pulley_radius_m": plant.pulley_radius_m,
            "amplifier_gains": list(plant.amplifier_gains or ()),
            "travel_m": {k: list(v) for k, v in plant.travel_m.items()},
            "extra": {
                "plant_parameters": Path(self.args.params).name,
                "seed": self.args.seed,
                "lockstep": self.args.lockstep,
            },  # fmt: skip
        }

    # -- the firmware --------------------------------------------------------------------------
    def serve(self) -> None:
        """The firmware's main loop: answer HELLO with INFO, run a sampling session on START."""
        while True:
            for frame_type, payload in self.poll(0.1):
                if frame_type == sp.HELLO:
                    self.send(sp.encode_info(self.info()))
                elif frame_type == sp.START and len(payload) == sp.START_PAYLOAD.size:
                    period_us, watchdog_ms = sp.START_PAYLOAD.unpack(payload)
                    self.run(period_us, watchdog_ms)

    def run(self, period_us: int, watchdog_ms: int) -> None:
        """Sample until STOP (or a fault injection ends it)."""
        args = self.args
        period = period_us * 1e-6
        watchdog = watchdog_ms * 1e-3
        lockstep_wait = min(watchdog / 2, 0.02)
        plant = self.make_plant(period)
        self.plant = plant
        sensors = plant.sensors
        zero_code = int(sensors.dac_code(0.0))
        n_in = len(plant.info.inputs)
        plant.start()
        command: tuple[int, int, int] | None = None
        # A closed limit switch cuts the outputs, latched until STOP, whatever the host sends
        # (the firmware's own protection; the host logger aborts the run as well).
        limit_cut = False
        last_command_at = time.perf_counter()
        t0 = time.perf_counter()
        k = 0
        while True:
            tripped = time.perf_counter() - last_command_at > watchdog
            if command is not None:  # before the first command the outputs are at 0 V
                codes = (zero_code, zero_code) if tripped or limit_cut else command[1:]
                plant.set_voltages(command[0], sensors.dac_volts(np.array(codes[:n_in])))
            sample = plant.read()
            limit_cut = limit_cut or any(sample.limits.values())
            if args.disconnect_after and k >= args.disconnect_after:
                os.close(self.fd)
                raise SystemExit(0)
            if args.stop_after and k >= args.stop_after:
                self.silent = True
            frame = self.sample_frame(sample, tripped)
            if args.drop_every and k % args.drop_every == args.drop_every - 1:
                frame = b""
            elif args.corrupt_every and k % args.corrupt_every == args.corrupt_every - 1:
                broken = bytearray(frame)
                broken[sp.HEAD.size + 9] ^= 0x5A
                frame = bytes(broken)
            if frame:
                self.send(frame)
            deadline = t0 + (k + 1) * period
            waited_from = time.perf_counter()
            polled = False
            while True:
                if args.lockstep:
                    if not frame or (command is not None and command[0] >= k):
                        break
                    timeout = waited_from + lockstep_wait - time.perf_counter()
                else:
                    timeout = deadline - time.perf_counter()
                if timeout <= 0 and polled:
                    break
                polled = True  # input is read every tick, even when running late
                for frame_type, payload in self.poll(timeout):
                    if frame_type == sp.COMMAND and len(payload) == sp.COMMAND_PAYLOAD.size:
                        command = sp.COMMAND_PAYLOAD.unpack(payload)
                        last_command_at = time.perf_counter()
                    elif frame_type == sp.STOP:
                        plant.stop()
                        self.send(sp.encode(sp.STOPPED))
                        return
                    elif frame_type == sp.HELLO:
                        self.send(sp.encode_info(self.info()))
            k += 1

    def sample_frame(self, sample, watchdog: bool) -> bytes:
        """One SAMPLE frame for ``sample``: counts, laser readings [nm], flags and DAC codes."""
        info = self.plant.info
        flags = sp.WATCHDOG if watchdog else 0
        for name, closed in sample.limits.items():
            if closed:
                flags |= sp.LIMIT_BITS[name]
        lasers = {"x": 0, "y": 0}
        for axis, value, valid in zip(info.lasers, sample.laser_m, sample.laser_valid,
                                      strict=True):  # fmt: skip
            if math.isnan(value):
                flags |= sp.LASER_X_NONE if axis == "x" else sp.LASER_Y_NONE
            else:
                lasers[axis] = round(value * 1e9)
            if valid:
                flags |= sp.LASER_X_VALID if axis == "x" else sp.LASER_Y_VALID
        counts = dict(zip(info.encoders, sample.encoder_counts, strict=True))
        applied = np.zeros(2)
        applied[: len(sample.applied_v)] = sample.applied_v
        applied_codes = [int(c) for c in self.plant.sensors.dac_code(applied)]
        cmd = sp.NO_COMMAND if sample.command_sequence is None else sample.command_sequence
        payload = sp.SAMPLE_PAYLOAD.pack(
            sample.sequence, sample.device_time_us, counts.get("phi1", 0), counts.get("phi2", 0),
            lasers["x"], lasers["y"], flags, applied_codes[0], applied_codes[1], cmd,
        )  # fmt: skip
        return sp.encode(sp.SAMPLE, payload)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The emulator's command line (module docstring); ``--travel`` as (axis, min, max) [m]."""
    parser = argparse.ArgumentParser(
        prog="python -m hframe_id.rig.emulator",
        description="Emulated rig microcontroller on a pseudo-terminal (sim plant inside).",
    )
    parser.add_argument("--params", required=True, help="plant parameter file")
    parser.add_argument("--seed", type=int, default=0, help="sensor noise seed")
    parser.add_argument("--period-us", type=int, default=1000, help="sample period [us]")
    parser.add_argument(
        "--lockstep",
        action="store_true",
        help="wait for each sample's command (deterministic; test aid)",
    )
    parser.add_argument(
        "--travel",
        nargs=3,
        action="append",
        metavar=("AXIS", "MIN", "MAX"),
        help="limit switch positions of an axis [m]",
    )
    parser.add_argument("--link", help="also make a symlink to the pty here")
    for name in ("corrupt-every", "drop-every", "stop-after", "disconnect-after"):
        parser.add_argument(f"--{name}", type=int, default=0, metavar="N")
    args = parser.parse_args(argv)
    if args.travel:
        args.travel = [(a, float(lo), float(hi)) for a, lo, hi in args.travel]
    return args


def main(argv: list[str] | None = None) -> int:
    """Open a pseudo-terminal, print ``PORT <path>``, serve until interrupted; returns 0."""
    args = parse_args(argv)
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    name = os.ttyname(slave)
    if args.link:
        link = Path(args.link)
        link.unlink(missing_ok=True)
        link.symlink_to(name)
    emulator = Emulator(master, args)
    print(f"PORT {name}", flush=True)
    try:
        emulator.serve()
    except KeyboardInterrupt:
        pass
    finally:
        print(json.dumps({"overruns": emulator.overruns}), file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
