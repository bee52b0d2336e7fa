"""Time windows for FRF estimation (Ewins 2000 §3.7; Brandt 2011 §9.3).

A window is named by a spec string: ``rect``, ``hann``, ``flattop``, ``force:W`` (unit for the first
fraction ``W`` of the record, then zero; default 0.05) and ``exponential:E`` (decays from 1 to ``E`` at
the last sample; default 0.01).  The exponential window adds a known decay rate ``-ln(E)/T`` (1/s) to
every pole, which :func:`remove_added_damping` takes back out of identified poles.
"""

from __future__ import annotations

import numpy as np

from flexmodal.modal.errors import ModalError

WINDOW_NAMES = ("rect", "hann", "flattop", "force", "exponential")
_DEFAULTS = {"force": 0.05, "exponential": 0.01}  # the one home of the impact-window defaults
# cosine-sum coefficients a_k of w[n] = sum_k (-1)^k a_k cos(2 pi k n / N): Hann, and the flat top of
# D'Antona & Ferrero (2006) that scipy.signal.windows.flattop uses
_COSINE_SUMS = {"hann": (0.5, 0.5),
                "flattop": (0.21557895, 0.41663158, 0.277263158, 0.083578947, 0.006947368)}


def parse_window(spec: str) -> tuple[str, float | None]:
    """Split ``name[:param]`` and check it; returns (name, param or None)."""
    name, _, param = spec.strip().lower().partition(":")
    name = {"rectangular": "rect", "none": "rect", "boxcar": "rect", "hanning": "hann",
            "flat-top": "flattop", "exp": "exponential"}.get(name, name)
    if name not in WINDOW_NAMES:
        raise ModalError(f"window {spec!r}: unknown name (use one of {', '.join(WINDOW_NAMES)})")
    if not param:
        return name, _DEFAULTS.get(name)
    if name not in _DEFAULTS:
        raise ModalError(f"window {spec!r}: {name} takes no parameter")
    try:
        value = float(param)
    except ValueError:
        raise ModalError(f"window {spec!r}: parameter {param!r} is not a number") from None
    if not 0.0 < value <= 1.0:
        raise ModalError(f"window {spec!r}: parameter must be in (0, 1]")
    return name, value


def impact_windows(spec: str | None) -> tuple[str, str]:
    """Full (force, exponential) window specs of an impact ``window`` option ``force:W,exponential:E``
    (either part optional, ``None`` for both): a missing force part is ``force:0.05``; a missing
    exponential part is ``exponential:1``, no window on the responses; ``exponential`` without its
    parameter is ``exponential:0.01``.

    The responses are left unwindowed unless asked: an exponential window adds its decay to every
    pole (Ewins 2000 §3.7; Fladung & Rost 1997, MSSP 11(1) 23-36), and when that decay exceeds a
    lightly damped mode's own (1 % at the end of an 8 s hit adds 0.58 1/s; a 20 Hz mode at 0.25 %
    decays at 0.31 1/s) the damping that remains after removing it is a small difference of two
    large numbers.  A record that truncates a free decay does not need the window for its poles: the
    DFT of a decay cut at the record's end is a rational function of z = exp(i omega dt) with the
    decay's own pole (only its residue changes), which a z-domain estimator (pLSCF) fits as it is.
    On the real-data corpus (benchmarks/realdata.py) the unwindowed responses give damping within the
    reference's spread on the three impact records where 1 % at the end did not.

    Examples
    --------
    >>> impact_windows(None)
    ('force:0.05', 'exponential:1')
    >>> impact_windows("force:0.1,exponential")
    ('force:0.1', 'exponential:0.01')
    >>> impact_windows("exp:0.5")
    ('force:0.05', 'exponential:0.5')
    """
    parts: dict[str, str] = {}
    for part in (spec or "").split(","):   # a loop over the two parts of the option
        if not part.strip():
            continue
        name, _ = parse_window(part)   # an unknown name or a bad parameter names itself
        if name not in _DEFAULTS:
            raise ModalError(f"window {spec!r}: {name} is a window for random runs; an impact run takes "
                             "'force:W,exponential:E' (either part optional)")
        if name in parts:
            raise ModalError(f"window {spec!r}: {name} is given twice")
        parts[name] = part.partition(":")[2].strip()
    parts.setdefault("exponential", "1")
    return tuple(f"{name}:{parts.get(name) or f'{_DEFAULTS[name]:g}'}" for name in ("force", "exponential"))


def window(spec: str, n: int) -> np.ndarray:
    """Window samples [n] for a spec string (periodic Hann / flat-top as used for Welch averaging:
    period ``n``, as ``scipy.signal.get_window(name, n, fftbins=True)``)."""
    name, param = parse_window(spec)
    if name == "rect":
        return np.ones(n)
    if name in _COSINE_SUMS:
        phase = 2 * np.pi * np.arange(n) / n
        return sum((-1) ** k * a * np.cos(k * phase) for k, a in enumerate(_COSINE_SUMS[name]))
    if name == "force":
        w = np.zeros(n)
        w[: max(1, int(param * n))] = 1.0
        return w
    return np.exp(np.log(param) * np.arange(n) / (n - 1))


def added_decay_rate_per_s(spec: str, n: int, sample_rate_hz: float) -> float:
    """Decay rate sigma (1/s) an exponential window of ``n`` samples adds to each pole (0 otherwise)."""
    name, param = parse_window(spec)
    if name != "exponential":
        return 0.0
    return max(0.0, -np.log(param) * sample_rate_hz / (n - 1))   # exponential:1 adds none (not -0)


def remove_added_damping(freq_hz: np.ndarray, damping_ratio: np.ndarray,
                         decay_rate_per_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(fn_hz, zeta) of the poles without the exponential window: the window shifts each pole's real
    part by ``-sigma_w`` and leaves the damped frequency alone, so subtract sigma_w and recombine."""
    wn = 2 * np.pi * np.asarray(freq_hz, float)
    sigma = np.asarray(damping_ratio, float) * wn - decay_rate_per_s
    wd = wn * np.sqrt(np.clip(1 - np.asarray(damping_ratio, float) ** 2, 0, None))
    wn_true = np.hypot(sigma, wd)
    return wn_true / (2 * np.pi), sigma / wn_true
