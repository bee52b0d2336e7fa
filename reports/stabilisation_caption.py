"""The caption of a run's stabilisation diagram in words a reviewer reads: what the axes are, what each
symbol means (with the stability criteria and units), and why the model order was chosen.

The identification's order note (``modal.identify.Modes.order_note``) is written for the command line
(``model order 54: 3 modes, the modes found stopped growing (3 at order 24, 3 at 36, 3 at 54); ...``); here it
is said as sentences.  A note of another shape is quoted as it is.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from flexmodal.modal.order_note import BASIS_WORDS
from flexmodal.modal.stability import PICKED, STABLE_DAMPING_REL, STABLE_FREQ_REL, STABLE_MAC_MIN

_NOTE = re.compile(r"model order (?P<order>\d+): (?P<modes>\d+ modes?), (?P<why>.+?) "
                   r"\((?P<history>\d+ at order \d+(?:, \d+ at \d+)*)\)"
                   r"(?:; (?:they explain|it explains) (?P<shown>\d+) of "
                   r"(?P<peaks>\d+) clear CMIF peaks?)?(?P<rest>.*)")
_FIT = "|".join(re.escape(w) for w in BASIS_WORDS.values())
_BASIS = re.compile(rf"; of the two pLSCF fits, (?P<used>{_FIT}) is used: it explains (?P<n_used>\d+) "
                    r"clear CMIF peaks? at an FRF correlation of (?P<c_used>[\d.]+); "
                    rf"(?:{_FIT}) explains (?P<n_other>\d+) at (?P<c_other>[\d.]+)")


_WHY = {"the default cap (a higher one: --max-order)":
        "it reached the default cap (--max-order sets a higher one)"}


def order_words(note: str) -> str:
    """The order note of a pLSCF identification as sentences.

    Parameters
    ----------
    note : str
        ``Modes.order_note`` (modal.identify): the order used, the modes found at each order tried,
        the clear CMIF peaks they explain, the basis used (one reference) and whether the poles were
        picked from a stored diagram.

    Returns
    -------
    str
        Sentences ending in a full stop; the note itself, quoted, when it has another shape.

    Examples
    --------
    >>> print(order_words("model order 54: 3 modes, the modes found stopped growing (3 at order 24, 3 at 36, "
    ...                   "3 at 54); they explain 3 of 3 clear CMIF peaks; of the two pLSCF fits, the "
    ...                   "standard one is used: it explains 3 clear CMIF peaks at an FRF correlation of "
    ...                   "1.000; the one that puts noise poles at negative damping explains 3 at 0.998"))
    Model order 54 used; 3 modes found at orders 24, 36 and 54; the search stopped because the modes
    found stopped growing. The 3 modes explain all 3 clear CMIF peaks. Of the two pLSCF bases, z =
    exp(+iωΔt) is used (3 clear peaks explained, FRF correlation 1.000; exp(−iωΔt): 3, 0.998).
    >>> print(order_words("model order 36: 2 modes, the default cap (a higher one: --max-order) "
    ...                   "(1 at order 24, 2 at 36)"))
    Model order 36 used; modes found: 1 at order 24, 2 at 36; the search stopped because it reached the
    default cap (--max-order sets a higher one).
    >>> print(order_words("order 4"))
    Model order: order 4.
    """
    m = _NOTE.fullmatch(note.strip())
    if m is None:
        return f"Model order: {note.strip()}."
    history = [tuple(int(x) for x in h.replace("order ", "").split(" at ")) for h in m["history"].split(", ")]
    orders = [o for _, o in history]
    if len({n for n, _ in history}) == 1:
        tried = f"{m['modes']} found at order{'s' if len(orders) > 1 else ''}"
        tried += " " + _listed([str(o) for o in orders])
    else:
        tried = "modes found: " + ", ".join(f"{n} at {'order ' if k == 0 else ''}{o}"
                                            for k, (n, o) in enumerate(history))
    why = _WHY.get(m["why"], m["why"])
    best = ("" if int(m["order"]) == max(orders)
            else " (of the orders tried, the one whose modes explain the most clear CMIF peaks)")
    words = f"Model order {m['order']} used{best}; {tried}; the search stopped because {why}."
    if m["peaks"]:
        shown, peaks = int(m["shown"]), int(m["peaks"])
        n_modes = m["modes"].split()[0]
        words += (f" The {n_modes} modes explain " if n_modes != "1" else " The mode explains ")
        words += (f"all {peaks} clear CMIF peaks." if shown == peaks and peaks > 1
                  else f"{shown} of the {peaks} clear CMIF peak{'s' if peaks != 1 else ''}.")
    rest = m["rest"]
    basis = _BASIS.search(rest)
    if basis:
        used, other = ("+", "−") if basis["used"] == BASIS_WORDS[False] else ("−", "+")
        words += (f" Of the two pLSCF bases, z = exp({used}iωΔt) is used ({basis['n_used']} clear peaks "
                  f"explained, FRF correlation {basis['c_used']}; exp({other}iωΔt): "
                  f"{basis['n_other']}, {basis['c_other']}).")
        rest = rest[:basis.start()] + rest[basis.end():]
    if PICKED in rest:
        words += " The poles were re-picked from the stored diagram (identify --poles)."
        rest = rest.replace(PICKED, "")
    return words + (f" ({rest.strip('; ')})" if rest.strip("; ") else "")


def shape_clause(n_outputs: int) -> str:
    """The shape criterion's words in a stabilisation caption's list of stability criteria.

    Parameters
    ----------
    n_outputs : int
        Outputs (response channels) the poles' shapes span [count]: with one, a MAC is always 1, so
        stability in shape is not judged (modal.lscf._flags, used by pLSCF and SSI-cov alike).

    Returns
    -------
    str
        ``", shape MAC ≥ …"``, or ``"; one output: shape not judged"``, to follow the damping clause.

    Examples
    --------
    >>> shape_clause(5), shape_clause(1)
    (', shape MAC ≥ 0.98', '; one output: shape not judged')
    """
    return f", shape MAC ≥ {STABLE_MAC_MIN:g}" if n_outputs > 1 else "; one output: shape not judged"


def stabilisation_caption(label: str, freq_hz: Sequence[float], band_hz: tuple[float, float], unit: str,
                          n_outputs: int, order_note: str) -> str:
    """The caption of a run's stabilisation diagram (reports.plots.plot_identification_diagram).

    Parameters
    ----------
    label : str
        The run (``runs.h5::theta0-impact``).
    freq_hz : sequence of float
        The selected modes' natural frequencies [Hz].
    band_hz : (float, float)
        The identification band [Hz].
    unit : str
        The FRFs' unit (``(m/s²)/N``), the CMIF's.
    n_outputs : int
        Outputs of the FRFs [count]: with one, stability in shape is not judged.
    order_note : str
        ``Modes.order_note`` (see :func:`order_words`), or empty.

    Returns
    -------
    str

    Examples
    --------
    >>> print(stabilisation_caption("r::a", [28.96, 100.3], (5.0, 450.0), "(m/s²)/N", 5, ""))
    r::a: stabilisation diagram of the pLSCF identification. Horizontal: frequency [Hz]; left: model
    order [-], one row of poles per order tried; right: the CMIF (singular values of the FRF matrix)
    [(m/s²)/N], log scale, peaking at the modes. Filled dots: poles stable from one order to the next
    (frequency within 1 %, damping ratio within 5 %, shape MAC ≥ 0.98); open grey dots: the other poles;
    black crosses: the poles of the 2 selected modes, at 28.96 and 100.3 Hz (dotted lines); shaded: the
    identification band, 5-450 Hz.
    """
    shape = shape_clause(n_outputs)
    n = len(freq_hz)
    words = (f"{label}: stabilisation diagram of the pLSCF identification. Horizontal: frequency [Hz]; "
             "left: model order [-], one row of poles per order tried; right: the CMIF (singular values "
             f"of the FRF matrix) [{unit}], log scale, peaking at the modes. Filled dots: poles stable "
             f"from one order to the next (frequency within {100 * STABLE_FREQ_REL:g} %, damping ratio "
             f"within {100 * STABLE_DAMPING_REL:g} %{shape}); open grey dots: the other poles; black "
             f"crosses: the poles of the {n} selected mode{'s' if n != 1 else ''}, at "
             f"{_listed([f'{f:.4g}' for f in freq_hz])} Hz (dotted lines); shaded: the identification "
             f"band, {band_hz[0]:.4g}-{band_hz[1]:.4g} Hz.")
    return words + (f" {order_words(order_note)}" if order_note else "")


def _listed(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"
