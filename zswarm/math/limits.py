"""The bounds every value is held to, on the wire and in a scenario file.

A message that decodes but carries a value no experiment can produce is malformed, not
something for an agent's math to choke on (a gyro of 1e200 killed an agent in so3.exp); a
scenario is checked against the same bounds, so that what it declares can travel.
"""

MAX_ABS = 1e12  # any number: the largest legitimate one is the start's epoch (1.8e9 s); products of 25 stay finite
ROT_TOL = 1e-6  # |R^T R − I| and |det R − 1|, per entry, of every rotation
