"""The fingertip pads' friction, shared by the MJCF builder (`sim.model`) and the motion
model's friction rung in `vlr gap` (`sim.gap`): the pads' material, which a user of the real
hand knows (or measures) like the pads' radius. A light module, so that the `vlr` command
does not import MuJoCo to read three numbers.

Why these values: models/README.md "Contacts".
"""

SLIDE_FRICTION = 1.0        # rubber pad on plastic
TORSION_FRICTION = 0.001    # m; ~1 mm: MuJoCo's 10 mm default locks a pad's spin
ROLL_FRICTION = 0.0
