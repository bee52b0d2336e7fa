"""Acquisition: device drivers, session configs and the HDF5 run store."""
