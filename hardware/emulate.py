"""`vlr emulate --config FILE`: serve emulated motors for a config, to dry-run it.

Prints the pseudo-terminal path to put in the config's `bus.port`, then serves until Ctrl-C.
(`bus.port: emulator` instead runs the same emulator inside the backend's own process.)
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

from vlr.hardware.config import HardwareConfig, load_config
from vlr.hardware.control_table import TICKS_PER_REV
from vlr.hardware.emulator import Emulator, KinematicPlant, MotorPlant

#: Shaft angle of every motor at power-up in the emulator [ticks] (mid-turn).
START_SHAFT = 2048.0


def build_emulator(cfg: HardwareConfig) -> tuple[Emulator, MotorPlant]:
    """An (unstarted) emulator with the config's motor ids and its plant.

    Each finger's line goes taut `emulator.slack` metres of winding after power-up (at the
    stored zero's angle when the config has one), so the calibration probe has work to do.
    """
    per_metre = TICKS_PER_REV / (2.0 * math.pi * cfg.motion.spool_radius)
    slack = cfg.emulator.slack * per_metre
    taut, shafts, directions = {}, {}, {}
    for f in cfg.fingers:
        taut_shaft = float(f.zero % TICKS_PER_REV) if f.zero is not None else (
            START_SHAFT + f.direction * slack)
        taut[f.id] = taut_shaft
        shafts[f.id] = taut_shaft - f.direction * slack
        directions[f.id] = f.direction
    if cfg.spread is not None:
        shafts[cfg.spread.id] = START_SHAFT
    plant: MotorPlant
    if cfg.emulator.plant == "sim":
        from vlr.hardware.sim_plant import SimPlant

        plant = SimPlant(cfg, taut=taut)
    else:
        plant = KinematicPlant(taut=taut, directions=directions)
    return Emulator(cfg.ids, plant=plant, shafts=shafts), plant


def register(subparsers: Any) -> None:
    """Add the `emulate` subcommand (entry point group vlr.commands)."""
    p = subparsers.add_parser(
        "emulate", help="emulate the motors of a hardware config on a pseudo-terminal",
        description="Serve emulated DYNAMIXEL motors (Protocol 2.0, XM430) with the ids of "
                    "a hardware config, so that the config can be dry-run before touching a "
                    "motor. Put the printed port in the config's bus.port; Ctrl-C stops.")
    p.add_argument("--config", required=True, help="hardware config YAML")
    p.add_argument("--seconds", type=float, default=None,
                   help="stop after this many seconds (default: run until Ctrl-C)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    emulator, plant = build_emulator(cfg)
    port = emulator.start()
    try:
        print(f"emulating motors {list(cfg.ids)} ({cfg.emulator.plant} plant) on {port}")
        print(f"put this in {cfg.path}:  bus: {{port: {port}, baud: {cfg.bus.baud}}}")
        if cfg.emulator.plant == "sim":
            print("note: the simulated camera frames are served only in-process (bus.port: "
                  "emulator); through this port use camera.fake: blank or a real camera")
        print("(Ctrl-C to stop)", flush=True)
        deadline = None if args.seconds is None else time.monotonic() + args.seconds
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        emulator.stop()
        if hasattr(plant, "close"):
            plant.close()
        print(f"served {emulator.packets_served} packets; torque at exit: "
              f"{ {i: int(on) for i, on in emulator.torque().items()} }", flush=True)
    return 0
