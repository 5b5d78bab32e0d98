"""The fingertip pads' friction, shared by the MJCF builder (`sim.model`) and the motion
model's friction rung in `vlr gap` (`sim.gap`): the pads' material, which a user of the real
hand knows (or measures) like the pads' radius. A light module, so that the `vlr` command
does not import MuJoCo to read three numbers.

Why these values: models/README.md "Contacts".
"""

SLIDE_FRICTION = 1.0        # rubber pad on plastic
TORSION_FRICTION = 0.001    # m; ~1 mm: MuJoCo's 10 mm default locks a pad's spin
ROLL_FRICTION = 0.0
# The filter's pads slide at twice the sim's mu: in the model the grasp's statically
# indeterminate internal forces sit nearer the cone's edge than the sim's do (the baseball's
# left and right pads at 0.93 of mu 1 against the sim's 0.46), and at mu 1 the filter's
# particles nearest the truth run away (docs/DECISIONS.md).
FILTER_SLIDE_FRICTION = 2.0 * SLIDE_FRICTION
