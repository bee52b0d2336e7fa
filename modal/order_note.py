"""The words of identification's order note that a report caption reads back (constants only, so that
reports can quote them without importing the solver)."""

BASIS_WORDS = {False: "the standard one", True: "the one that puts noise poles at negative damping"}
"""The two pLSCF fits of one reference in the order note: basis z = exp(+i w dt) and exp(-i w dt)."""
