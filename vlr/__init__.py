"""VLR core: hardware-agnostic kinematics, motion and observation models, particle filter,
controller, AprilTag perception and the `vlr` CLI. Imports neither `sim` nor `hardware`."""
