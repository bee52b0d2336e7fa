"""A toy identification method, the whole of it: one mode at the line where the summed FRF magnitude
peaks, 1 % damping, the FRFs at that line as its shape."""

import numpy as np

from flexmodal.modal.identify import Poles
from flexmodal.modal.registry import Method, register_method

NAME = "max-line"


def run(inputs):
    """modal.identify.FrfInputs -> modal.identify.Poles."""
    k = int(np.argmax(np.abs(inputs.H).sum(axis=(0, 1))))
    shape = inputs.H[:, inputs.reference, k][:, None].astype(complex)
    return Poles(inputs.freq_hz[[k]], np.array([0.01]), shape, (), False, {})


register_method(NAME, Method("frf", run, "the line of the largest summed FRF magnitude (a toy)"))
