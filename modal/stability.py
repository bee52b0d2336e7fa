"""The stabilisation diagram's default stability criteria and the order note's mark of a re-pick:
plain constants, which the report's captions quote (reports may not import the solvers).

A pole is stable against the nearest pole one model order lower when its frequency and damping ratio
change by at most these relative amounts and its shape has at least this MAC with that pole's
(modal.lscf; with one output the shape is not judged).
"""

STABLE_FREQ_REL = 0.01      # relative frequency change [-]
STABLE_DAMPING_REL = 0.05   # relative damping-ratio change [-]
STABLE_MAC_MIN = 0.98       # least MAC of the shapes [-] (two or more outputs)
PICKED = "; poles picked from the stored diagram"   # ends the order note of a pick from modal.diagrams
