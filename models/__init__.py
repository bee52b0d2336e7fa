"""Model packages: planar FE frame, assumed-modes beams, lumped-mass and Blevins' formulas."""
