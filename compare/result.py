"""The diagnosis result: a tree of frozen records, written as diagnosis.json and read back from it.

:func:`flexmodal.compare.diagnosis.diagnose` returns a :class:`Diagnosis`.  ``Diagnosis.to_json()`` is
the text of diagnosis.json (docs/formats.md, "Diagnosis JSON", whose key table lists every field):
strict JSON (RFC 8259), so a number that is not finite is written ``null``; ``Diagnosis.from_json()``
reads it back and ``from_json(x.to_json()) == x``.

Units sit in the names as they do in the JSON: ``*_rel_error`` is a relative frequency error as a
fraction, (predicted - measured) / measured (0.05 = 5 %); ``*_hz`` is Hz; an effect parameter's name
ends with its SI unit (``k_Nm_per_rad``, ``mass_kg``).  Every number in the tree is a finite Python
``float``/``int`` or None (``null`` in the JSON: a missing number, e.g. the held-out prediction of a
configuration no fold held out).  The tree is immutable all the way down: sequences are tuples and
mappings are read-only ``FrozenMap`` objects keyed as in the JSON, so a record is also hashable.

A field whose default is None is optional: None means the key is absent from the JSON (a hand-written
file with only the keys of docs/formats.md loads; so does a ``none`` verdict, which has no fitted
parameters).  Keys this version does not know are ignored on reading.
"""

from __future__ import annotations

import functools
import json
import math
import types
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Self

from flexmodal.checked_io.percent import percent
from flexmodal.checked_io.text import loads_json, shown_value
from flexmodal.compare.errors import CompareError

MAX_COUNT = 10**6
"""Every whole number of the tree (mode numbers, ranks, counts of parameters, candidates and folds) lies
in 0..MAX_COUNT (contract.table.MAX_MODE: modes are numbered up to 10^6)."""

Hz = tuple[float | None, ...]
"""Frequencies [Hz] of modes 1..n of one configuration; None where there is no value."""


class FrozenMap(Mapping[str, Any]):
    """The read-only mapping of the tree (parameters, per-mode errors, frequency tables): equal to a
    dict with the same items, hashable, in the insertion order of the dict it was made from."""

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, Any] | None = None) -> None:
        self._items = dict(items or {})

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(frozenset(self._items.items()))

    def __repr__(self) -> str:
        return repr(self._items)


def _clean(value: object) -> object:
    """``value`` with numpy scalars and arrays made Python numbers and tuples, non-finite floats None,
    lists tuples and mappings FrozenMaps (recursively; records are left as they are)."""
    if isinstance(value, Mapping):
        return FrozenMap({str(k): _clean(v) for k, v in value.items()})
    if isinstance(value, list | tuple):
        return tuple(_clean(v) for v in value)
    if isinstance(value, bool | str | _Record) or value is None:
        return value
    if hasattr(value, "tolist"):                     # a numpy scalar or array: Python numbers
        return _clean(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


def _plain(value: object) -> object:
    """A field value as JSON data: records as dicts, tuples as lists."""
    if isinstance(value, _Record):
        return value.to_dict()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _kind(value: object) -> str:
    return "null" if value is None else type(value).__name__


def _key(where: str, name: str) -> str:
    """The key path ``name`` below ``where`` (``verdict.explained``; ``where`` empty at the top)."""
    return f"{where}.{name}" if where else name


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _load(tp: Any, value: object, where: str) -> object:
    """``value`` (parsed JSON) at the key path ``where`` checked against the type hint ``tp`` and
    converted to it; CompareError naming the path when it does not fit."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (types.UnionType, typing.Union):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        if inner is float and isinstance(value, float) and not math.isfinite(value):
            return None              # NaN/Infinity (not strict JSON): an optional number left out
        return _load(inner, value, where)
    if isinstance(tp, type) and issubclass(tp, _Record):
        if not isinstance(value, dict):
            raise CompareError(f"{where}: expected an object (got {_kind(value)})")
        return tp.from_dict(value, where)
    if origin is tuple:
        if not isinstance(value, list):
            raise CompareError(f"{where}: expected a list (got {_kind(value)})")
        return tuple(_load(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
    if origin is Mapping:
        if not isinstance(value, dict):
            raise CompareError(f"{where}: expected an object (got {_kind(value)})")
        return {k: _load(args[1], v, _key(where, k)) for k, v in value.items()}
    if tp is float:                  # a required number: finite (optional ones may be null, above)
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
        raise CompareError(f"{where}: expected a number (got {_kind(value)} {value!r})")
    whole = isinstance(value, int) and not isinstance(value, bool)
    if tp is int and not (whole and 0 <= value <= MAX_COUNT):
        raise CompareError(f"{where}: expected an integer from 0 to {MAX_COUNT} (got {_kind(value)} "
                           f"{value!r})")
    if tp in (str, bool) and not isinstance(value, tp):
        raise CompareError(f"{where}: expected {'text' if tp is str else 'true or false'} "
                           f"(got {_kind(value)} {value!r})")
    return value


class _Record:
    """Base of the records of the tree: construction normalises the values (:func:`_clean`);
    ``to_dict``/``from_dict`` map fields to JSON keys, a field with ``metadata={"suffix": S}`` holding
    the keys ``<name>S`` of its object as ``{name: value}``."""

    __slots__ = ()

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            object.__setattr__(self, f.name, _clean(getattr(self, f.name)))

    def to_dict(self) -> dict[str, object]:
        """The record as JSON data (dicts, lists, str, int, float, bool, None), keys in field order;
        an optional field (default None) that is None is left out."""
        out: dict[str, object] = {}
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if "suffix" in f.metadata:
                out.update({f"{k}{f.metadata['suffix']}": _plain(v) for k, v in value.items()})
            elif not (value is None and f.default is None):
                out[f.name] = _plain(value)
        return out

    def to_json(self) -> str:
        """The record as strict JSON text (no NaN or Infinity), indented by two spaces."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False)

    @classmethod
    def from_dict(cls, data: dict[str, object], where: str = "") -> Self:
        """The record from parsed JSON found at the key path ``where`` (empty: the document); a
        missing required key or a value of the wrong type is a CompareError naming its key path
        (``no 'verdict.explained'``, ``baseline.rms_rel_error: expected a number (got str '12 %')``)."""
        hints = _hints(cls)
        values: dict[str, object] = {}
        for f in fields(cls):  # type: ignore[arg-type]
            suffix = f.metadata.get("suffix")
            if suffix:
                inner = typing.get_args(hints[f.name])[1]
                values[f.name] = {k[:-len(suffix)]: _load(inner, v, _key(where, k))
                                  for k, v in data.items() if k.endswith(suffix)}
            elif f.name in data:
                values[f.name] = _load(hints[f.name], data[f.name], _key(where, f.name))
            elif f.default is not None:
                raise CompareError(f"no {_key(where, f.name)!r}")
        record = cls(**values)
        record._check(where)
        return record

    def _check(self, where: str) -> None:
        """Refuse values a document read back cannot hold (CompareError naming the key); by type only
        unless a record says more."""

    @classmethod
    def from_json(cls, text: str) -> Self:
        """The record from the JSON text of a document (``to_json``'s inverse); CompareError on text
        that is not JSON or not this record."""
        data = loads_json(text, "diagnosis", CompareError, "diagnosis document")
        if not isinstance(data, dict):
            raise CompareError(f"expected a JSON object (got {_kind(data)})")
        return cls.from_dict(data)


_RECORD = {"frozen": True, "slots": True, "kw_only": True}


@dataclass(**_RECORD)
class Baseline(_Record):
    """The nominal model against the measurement: RMS and largest relative error over all paired modes,
    RMS per mode number (``"1"``, ``"2"``, ...) and per configuration."""

    rms_rel_error: float
    max_rel_error: float
    per_mode: Mapping[str, float]
    per_config: Mapping[str, float]

    def _check(self, where: str) -> None:
        """Errors are RMS or absolute fractions (>= 0); per_mode is keyed by mode numbers 1, 2, ..."""
        errors = {"rms_rel_error": self.rms_rel_error, "max_rel_error": self.max_rel_error,
                  **{f"per_mode.{k}": v for k, v in self.per_mode.items()},
                  **{f"per_config.{k}": v for k, v in self.per_config.items()}}
        for key, value in errors.items():
            if value is not None and value < 0:
                raise CompareError(f"{_key(where, key)}: {value!r} is negative (an error fraction is >= 0)")
        for mode in self.per_mode:
            if not (mode.isascii() and mode.isdigit() and len(mode) <= 7 and 1 <= int(mode) <= MAX_COUNT):
                raise CompareError(f"{_key(where, 'per_mode')}: key {shown_value(mode, 40)} is not a mode "
                                   f"number (1, 2, ... {MAX_COUNT})")


@dataclass(**_RECORD)
class Where(_Record):
    """Where the gap lies: the modes and configurations that carry it and the region of the arm it points
    to (``joint:<j>``, ``link:<l>``, ``member:<m>``, ``point:<l>@<f>``, ``base``, ``tip``, ``sensors``;
    all empty for a ``none`` verdict).  ``region_scores``: R^2 [-] of each region's sensitivities;
    ``mac_per_mode`` [-] and ``comac`` [-] per sensor when shapes were measured."""

    modes: tuple[int, ...]
    configs: tuple[str, ...]
    region: str
    region_scores: Mapping[str, float] | None = None
    mac_per_mode: Mapping[str, float | None] | None = None
    comac: Mapping[str, float | None] | None = None


@dataclass(**_RECORD)
class CandidateScore(_Record):
    """One cross-validated candidate of the ranking: ``effect`` (effects joined by ``+``) at ``location``
    with its fitted ``params`` (SI, unit in the name); ``fit_rms_rel_error`` over all configurations,
    ``heldout_rms_rel_error``/``heldout_max_rel_error`` over the held-out ones, ``n_params`` fitted,
    ``score`` the ranking key (lower is better), ``mac_mean`` [-] of the paired shapes and
    ``heldout_shape_rms_error`` [-], sqrt(mean(1 - MAC) / (sensors - 1)) of the held-out shapes."""

    effect: str
    location: str
    params: Mapping[str, float | None]
    fit_rms_rel_error: float
    n_params: int
    mac_mean: float | None = None
    heldout_rms_rel_error: float
    heldout_max_rel_error: float | None = None
    heldout_shape_rms_error: float | None = None
    score: float
    params_at_bound: tuple[str, ...] | None = None
    unidentified_params: tuple[str, ...] | None = None


@dataclass(**_RECORD)
class Remaining(_Record):
    """One of the largest held-out errors the verdict leaves: ``mode`` (from 1) at ``config``."""

    config: str
    mode: int
    heldout_rel_error: float | None


@dataclass(**_RECORD)
class Alternative(_Record):
    """A candidate as good as the verdict's within noise, and the measurement that would separate them:
    pose ``separate_at`` (``<pose var>=<value>``), model mode ``separate_mode``, where their frequencies
    differ by ``separate_rel_diff`` (fraction); the three are None when no pose separates them."""

    effect: str
    location: str
    params: Mapping[str, float | None]
    heldout_rms_rel_error: float
    separate_at: str | None = None
    separate_mode: int | None = None
    separate_rel_diff: float | None = None


MIN_CHANCE = 0.05
"""The least ``decide_chance`` of an advised pose (``NextMeasurement``, compare/next_measurement.py): on
the used blind draws 421-425 and 526-530 (69 verdicts advised by the ranking alone), the advised pose
resolved 3 of the 46 verdicts whose best chance was below it, no better than a random untested pose
(9/138), and 7/23 of the others (random 10/69)."""


@dataclass(**_RECORD)
class NextMeasurement(_Record):
    """An untested pose (``<pose var>=<value>``, or ``<var>=<value>,<var>=<value>`` for several pose
    variables at once) worth measuring next, the model mode that carries most of its value, the expected
    information [nats] it brings on the choice between the verdict and its alternatives (mean
    Kullback-Leibler divergence of their predictions), and ``decide_chance`` the chance (0-1) that
    one measurement there leaves the verdict unambiguous (compare/next_measurement.py); ``beyond`` how
    far the pose lies beyond the measured range (``60 deg beyond the measured theta_deg 0..120 deg``; None
    inside it: the rig does not say whether the arm reaches it)."""

    pose: str
    mode: int
    information_nats: float
    decide_chance: float | None = None
    beyond: str | None = None


@dataclass(**_RECORD)
class Verdict(_Record):
    """The chosen explanation (``effect`` ``"none"`` and ``location`` ``""`` when no effect is needed or
    none helps) and the held-out RMS error before and after it.  For a fitted effect: its ``params``
    (the identified ones), ``unidentified_params``, ``params_at_bound``, ``structured_residuals``, the
    ``remaining`` largest held-out errors and ``ambiguous``.  The graded verdict: ``ranked`` the
    verdict's place in ``ranking`` (1 = top) and ``why_not_top`` when it is not first; ``grade``
    (``explained``, ``largely explained``, ``partly explained``, ``not explained``), ``gap_removed``
    the fraction of the held-out RMS gap removed (1 - after/before), ``remaining_over_scatter`` the
    held-out RMS after over the measurement scatter, ``residual_feature`` what in the residual points
    outside the library (a pose trend, one mode, one configuration, one sensor; empty when nothing
    does) and ``flags`` the warnings that go with the verdict (e.g. a shape that disagrees at one
    sensor); ``param_intervals`` a 95 % interval ``[low, high]`` per fitted parameter (SI) and
    ``interval_method`` how they were computed; ``heldout_in_prediction_interval`` ``[inside, all]``:
    the held-out frequencies inside their 95 % prediction interval from the fold that did not see
    them; ``next_measurements`` the untested poses most likely to decide between the verdict and its
    rivals of another effect or place (empty when it has none; when every alternative only adds a
    component, the summary says why no pose is advised).  ``per_config``: pose-dependent parameters
    per configuration, ``{name: {config: value}}``, written as the keys ``<name>_per_config``."""

    effect: str
    location: str
    heldout_rms_rel_error_before: float
    heldout_rms_rel_error_after: float
    explained: bool
    params: Mapping[str, float | None] | None = None
    unidentified_params: tuple[str, ...] | None = None
    params_at_bound: tuple[str, ...] | None = None
    structured_residuals: bool | None = None
    remaining: tuple[Remaining, ...] | None = None
    alternatives: tuple[Alternative, ...] | None = None
    ambiguous: bool | None = None
    summary: str | None = None
    ranked: int | None = None
    why_not_top: str | None = None
    grade: str | None = None
    gap_removed: float | None = None
    remaining_over_scatter: float | None = None
    residual_feature: str | None = None
    flags: tuple[str, ...] | None = None
    param_intervals: Mapping[str, tuple[float | None, ...]] | None = None
    interval_method: str | None = None
    heldout_in_prediction_interval: tuple[int, ...] | None = None
    next_measurements: tuple[NextMeasurement, ...] | None = None
    per_config: Mapping[str, Mapping[str, float | None]] = field(default_factory=FrozenMap,
                                                              metadata={"suffix": "_per_config"})


@dataclass(**_RECORD)
class CandidateCount(_Record):
    """Candidates fitted to all configurations, and those of them cross-validated."""

    fitted: int
    cross_validated: int


@dataclass(**_RECORD)
class ScatterSource(_Record):
    """Where the relative measurement scatter came from (compare/gap.py ``estimate_scatter``):
    ``repeated configurations``, ``freq_std_hz column`` or ``--scatter (fallback)``, and how;
    ``measurement`` that scatter (fraction) and ``model_form_floor`` (fraction) the held-out error of
    the best candidate beyond it: the ranking's ``scatter`` is ``sqrt(measurement^2 + floor^2)``, or
    ``least`` (fraction: the least scatter the ranking uses, compare/diagnosis.py ``MIN_SCATTER``) when
    that sum is below it (else None)."""

    source: str
    detail: str
    measurement: float | None = None
    model_form_floor: float | None = None
    least: float | None = None


@dataclass(**_RECORD)
class Holdout(_Record):
    """The cross-validation scheme (e.g. ``leave-one-configuration-out``) and its number of folds."""

    scheme: str
    n_folds: int


@dataclass(**_RECORD)
class Predictions(_Record):
    """Frequencies [Hz] per configuration: measured, of the nominal model, of the best candidate fitted
    to all configurations and as predicted by the fold that held each configuration out."""

    measured_hz: Mapping[str, Hz]
    baseline_hz: Mapping[str, Hz]
    best_fit_hz: Mapping[str, Hz] | None = None
    best_heldout_hz: Mapping[str, Hz] | None = None

    def rms_rel_error_per_mode(self, predicted: Mapping[str, Hz]) -> Mapping[str, float | None]:
        """RMS over configurations of ``f_predicted / f_measured - 1`` per mode ({"1": fraction, ...}) of
        one of the tables (e.g. ``self.best_heldout_hz``) against ``measured_hz``; configurations or
        values it lacks (None) are left out; None for a mode with no pair at all."""
        import numpy as np

        configs = [c for c in self.measured_hz if c in predicted]
        n = max((len(self.measured_hz[c]) for c in configs), default=0)

        def grid(table: Mapping[str, Hz]) -> np.ndarray:
            rows = [[np.nan if v is None else v for v in table[c][:n]] for c in configs]
            return np.array([r + [np.nan] * (n - len(r)) for r in rows], float).reshape(len(configs), n)

        err = grid(predicted) / grid(self.measured_hz) - 1.0
        count = np.isfinite(err).sum(axis=0)
        mean_square = np.nansum(err**2, axis=0) / np.maximum(count, 1)
        return {str(m + 1): float(np.sqrt(mean_square[m])) if count[m] else None for m in range(n)}


@dataclass(**_RECORD)
class Diagnosis(_Record):
    """A sim-to-real gap diagnosis (docs/diagnosis.md): the baseline gap, where it lies, the ranking of
    candidates (best first), the verdict, and the data it was judged on: the relative measurement
    ``scatter`` (fraction) and its source, the hold-out scheme, the configurations and the frequencies;
    ``warnings`` about measured shapes it could not use."""

    baseline: Baseline
    where: Where
    ranking: tuple[CandidateScore, ...]
    verdict: Verdict
    n_candidates: CandidateCount | None = None
    scatter: float | None = None
    scatter_source: ScatterSource | None = None
    holdout: Holdout | None = None
    configs: tuple[str, ...] | None = None
    predictions: Predictions | None = None
    # a line per reason why the measured shapes of some configurations paired no modes by MAC (paired by
    # frequency order: compare.tables.shape_warnings, a zero shape its MAC 0/0), and one when the rig sets
    # shear (compare.verdict_text.SHEAR_UNCALIBRATED); None when there is none
    warnings: tuple[str, ...] | None = None

    def verdict_score(self) -> CandidateScore | None:
        """The verdict's entry of ``ranking`` (its fitted parameters, unidentified ones included, and its
        errors): the one at the verdict's place ``verdict.ranked`` (1 = first); None for a ``none``
        verdict, or one ranked below the entries kept."""
        rank = self.verdict.ranked
        return self.ranking[rank - 1] if rank is not None and 1 <= rank <= len(self.ranking) else None

    # -- notebook display (reports engineer's block: to_frame, __repr__, _repr_html_) -----------------
    def to_frame(self):
        """The ranking of candidate effects as a pandas DataFrame, best first: ``rank``, ``effect``,
        ``location``, ``n_params``, ``fit_rms_rel_error_pct`` and ``heldout_rms_rel_error_pct`` [%], and
        one column per fitted parameter (its name carries its unit, ``k_Nm_per_rad``; empty where the
        candidate has no such parameter)."""
        import pandas as pd

        rows = [{"rank": k + 1, "effect": r.effect, "location": r.location, "n_params": r.n_params,
                 "fit_rms_rel_error_pct": 100 * r.fit_rms_rel_error,
                 "heldout_rms_rel_error_pct": 100 * r.heldout_rms_rel_error, **dict(r.params)}
                for k, r in enumerate(self.ranking)]
        return pd.DataFrame(rows, columns=None if rows else ["rank", "effect", "location", "n_params",
                                                             "fit_rms_rel_error_pct",
                                                             "heldout_rms_rel_error_pct"])

    def _verdict_line(self) -> str:
        v = self.verdict
        named = f"{v.effect} at {v.location}" if v.location else v.effect
        return (f"{named}; held-out RMS error {percent(v.heldout_rms_rel_error_before)} -> "
                f"{percent(v.heldout_rms_rel_error_after)}; "
                + (v.grade or ("explained" if v.explained else "not explained")))

    def __repr__(self) -> str:
        return (f"Diagnosis({self._verdict_line()}; baseline RMS {percent(self.baseline.rms_rel_error)}, "
                f"{len(self.ranking)} candidates ranked)")

    def _repr_html_(self) -> str:
        import html

        from flexmodal.contract.table import display_html

        shown = self.to_frame().head(8).rename(columns={"fit_rms_rel_error_pct": "fit RMS error [%]",
                                                        "heldout_rms_rel_error_pct": "held-out RMS error [%]",
                                                        "n_params": "parameters [count]"})
        return display_html(f"Diagnosis: <b>{html.escape(self._verdict_line())}</b>; baseline RMS error "
                            f"{percent(self.baseline.rms_rel_error)} (candidates, best first; "
                            "<code>to_frame()</code> has all)", shown.round(4))

    def after_hz(self) -> Mapping[str, Hz] | None:
        """The best candidate's frequencies the gap after it is judged on: its held-out predictions, or
        its fit to all configurations when none of them was held out; None without a best candidate.

        Returns
        -------
        Mapping[str, tuple of (float or None)] or None
            Per configuration, the natural frequency of each mode in order [Hz] (None where that
            configuration was not predicted, e.g. one fitted rather than held out):
            ``predictions.best_heldout_hz``, else ``predictions.best_fit_hz``; None when neither holds a
            frequency to compare with the measured ones.

        Examples
        --------
        >>> import flexmodal as fm
        >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
        ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
        ...                      holdout="theta30,theta90,theta150")   # one candidate: quick
        >>> after = result.after_hz()
        >>> after is result.predictions.best_heldout_hz   # judged on what the fit did not see
        True
        >>> sorted(c for c, freq_hz in after.items() if freq_hz[0] is not None)
        ['theta150', 'theta30', 'theta90']
        """
        pred = self.predictions
        for table in (pred.best_heldout_hz, pred.best_fit_hz) if pred is not None else ():
            if table and any(v is not None for v in pred.rms_rel_error_per_mode(table).values()):
                return table
        return None

    def per_mode_after(self) -> Mapping[str, float | None] | None:
        """RMS relative error per mode with the best candidate (:meth:`after_hz`; :meth:`per_mode_before`
        is the nominal model's on the same configurations); None without a best candidate."""
        table = self.after_hz()
        return None if table is None else self.predictions.rms_rel_error_per_mode(table)

    def per_mode_before(self) -> Mapping[str, float | None]:
        """RMS relative error per mode of the nominal model over the configurations and modes
        :meth:`per_mode_after` is judged on (like for like: held out against held out); over every
        configuration (``baseline.per_mode``) without a best candidate.

        Returns
        -------
        Mapping[str, float or None]
            Per mode number (``"1"``, ``"2"``, ...), the RMS over those configurations of
            ``f_nominal / f_measured - 1`` [fraction, not %]; None for a mode with no pair.

        Examples
        --------
        The nominal model's error on the three held-out poses, against the same RMS by hand:

        >>> import numpy as np
        >>> import flexmodal as fm
        >>> result = fm.diagnose("examples/rigs/seed003_two_link.toml",
        ...                      "examples/measured/seed003_table3_f1f2.csv", effects="joint_stiffness",
        ...                      holdout="theta30,theta90,theta150")   # one candidate: quick
        >>> pred = result.predictions
        >>> err = np.array([[pred.baseline_hz[c][k] / pred.measured_hz[c][k] - 1 for k in range(2)]
        ...                 for c in ("theta30", "theta90", "theta150")])
        >>> before = result.per_mode_before()
        >>> bool(np.allclose([before["1"], before["2"]], np.sqrt((err ** 2).mean(axis=0)), rtol=1e-12))
        True
        >>> before == result.baseline.per_mode   # not the error over all six poses
        False
        """
        table = self.after_hz()
        if table is None:
            return self.baseline.per_mode
        base = self.predictions.baseline_hz
        same = {c: tuple(None if a is None or k >= len(base.get(c, ())) else base[c][k]
                         for k, a in enumerate(after))
                for c, after in table.items() if c in base}
        return self.predictions.rms_rel_error_per_mode(same)
