"""The real Yale OpenHand Model O behind `vlr.hand.Hand` (`--backend hardware`).

DYNAMIXEL X-series tendon motors through dynamixel_sdk, a USB palm camera, one YAML config,
and a Protocol 2.0 motor emulator for dry runs and tests. See hardware/README.md.
"""
