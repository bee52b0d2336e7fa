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

# SSI-cov (modal.ssi): its poles are kept only when physical, then judged as above but for the damping
SSI_MPC_MIN = 0.7       # poles below this modal phase collinearity are noise (real modes have MPC ~ 1)
SSI_MPD_MAX_DEG = 30.0  # poles whose entries scatter more than this from one phase line [deg] are noise
SSI_ZETA_MAX = 0.2      # poles damped more than 20 % are not structural modes of an arm
# SSI damping estimates scatter more between orders than pLSCF's; 5 % (the input-output path's) left
# the demo arm's third mode stable in only 62 % of the orders, 20 % keeps 90 % (pyOMA2 uses 10 %)
SSI_STABLE_DAMPING_REL = 0.2
