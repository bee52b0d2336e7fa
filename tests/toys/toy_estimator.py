"""A toy FRF estimator, the whole of it: the arithmetic mean of H1 and H2."""

from flexmodal.modal.frf import h1, h2
from flexmodal.modal.registry import register_estimator

NAME = "Hmean"


def h_mean(spectra):
    """H [n_out, n_in, n_freq]: the mean of the H1 and H2 estimates of the averaged ``spectra``."""
    return 0.5 * (h1(spectra) + h2(spectra))


register_estimator(NAME, h_mean)
