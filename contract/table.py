"""Modal table (docs/formats.md): one row per (configuration, mode), read from and written to CSV.

Required columns ``config`` (str), ``mode`` (1-based int), ``freq_hz``; optional ``damping_ratio``,
``source``, ``pose.<name>`` and ``shape.<sensor>`` (real, or complex written as ``0.1+0.2j``).
Extra columns are kept.  The table is shared by the modal engine (measured), the model packages
(predicted) and the comparison layer.
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from flexmodal.checked_io.csv_tables import read_table
from flexmodal.checked_io.data_range import MIN_PEAK
from flexmodal.checked_io.output import atomic_path
from flexmodal.checked_io.text import name_fault, natural_order
from flexmodal.contract.errors import ContractError

REQUIRED = ("config", "mode", "freq_hz")
POSE_PREFIX = "pose."
SHAPE_PREFIX = "shape."
UNIT_SUFFIXES = {"_deg": "deg", "_kg": "kg", "_m": "m", "_rad": "rad", "_n": "N"}   # pose_unit
STD_COLUMNS = ("freq_std_hz", "damping_std")   # uncertainty of identification: >= 0, empty when unknown
MAP_COLUMN = "n_windows"   # windows behind a row of a modal map (identify --track): its mark
MAX_MODE = 1e6           # mode numbers are whole, 1..1e6
MAX_FREQ_HZ = 1e9        # no structural mode is above 1 GHz; (2 pi f)^2 of 1e308 Hz overflows
MAX_POSE = 1e12          # no pose value is larger (the diagnosis takes powers of pose spans)
MAX_MAGNITUDE = 1e150    # shapes, uncertainties: their squares must stay finite
TINIEST = np.finfo(float).tiny   # 2.2e-308: a nonzero value below it (subnormal) is read as 0


def pose_unit(var: str) -> str:
    """Unit of a pose variable from its name's suffix (``theta_deg`` -> deg), ``-`` if none.

    Examples
    --------
    >>> pose_unit("theta_deg"), pose_unit("payload_kg"), pose_unit("slot")
    ('deg', 'kg', '-')
    """
    for suffix, unit in UNIT_SUFFIXES.items():
        if var.lower().endswith(suffix):
            return unit
    return "-"


def _parse_complex(value: object) -> complex:
    if isinstance(value, bool | np.bool_):   # True is not 1: ValueError, as for text that is no number
        raise ValueError(f"{value!r} is not a number")
    if isinstance(value, int | float | complex | np.number):
        return complex(value)
    text = str(value).strip().replace(" ", "").replace("i", "j")
    if text.startswith("(") and text.endswith(")"):
        text = text[1:-1]
    return complex(text)


def _floats(column: pd.Series) -> pd.Series:
    """``column`` as floats, NaN where a value is none: text, or a whole number too large for a float
    (thousands of digits, which pandas cannot convert at once)."""
    if pd.api.types.is_bool_dtype(column.dtype) or (   # bool and pandas' nullable boolean (a numeric dtype)
            not pd.api.types.is_numeric_dtype(column)   # other numbers hold no True: no scan
            and column.map(lambda v: isinstance(v, bool | np.bool_)).any()):
        column = column.map(lambda v: None if isinstance(v, bool | np.bool_) else v)   # True is not 1
    try:
        return pd.to_numeric(column, errors="coerce").astype(float)
    except OverflowError:
        fitting = column.map(lambda v: v if _fits_float(v) else None)
        return pd.to_numeric(fitting, errors="coerce").astype(float)


def _fits_float(value: object) -> bool:
    try:
        float(value)
    except OverflowError:
        return False
    except (TypeError, ValueError):
        pass
    return True


def _numbers(column: pd.Series, name: str, source: str, limit: float = MAX_MAGNITUDE) -> pd.Series:
    """``column`` as finite floats (empty cells stay NaN: not given; -0 and subnormal numbers are 0);
    text, an infinity or a magnitude above ``limit`` raises ContractError naming the row (header =
    row 1) and the value."""
    values = _floats(column)
    values = values.where(~(values.abs() < TINIEST), 0.0)
    given = column.notna()
    if not pd.api.types.is_numeric_dtype(column):   # text: a blank cell is not given (numbers: no scan)
        given &= column.astype(str).str.strip() != ""
    bad = given & (values.isna() | np.isinf(values))
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        value = column.iloc[row]
        shown = repr(value) if isinstance(value, str) else value
        raise ContractError(f"{source}: row {row + 2}: column {name!r} is not a finite number ({shown})")
    odd = values.abs() > limit
    if odd.any():
        row = int(np.flatnonzero(odd.to_numpy())[0])
        raise ContractError(f"{source}: row {row + 2}: {name} = {values.iloc[row]:g} is above {limit:g} in "
                            "magnitude")
    return values


def _shape_values(col: str, cells: np.ndarray, source: str) -> np.ndarray:
    """The values of shape column ``col`` (its cells: numbers, or text such as ``0.1+0.2j``) as floats,
    or complex numbers when one has an imaginary part; NaN where empty, subnormal parts 0.  Text that is
    no number, an infinite value, a complex number with one NaN part and a magnitude above
    :data:`MAX_MAGNITUDE` raise ContractError naming the row (header = row 1)."""
    try:
        values = (cells.astype(complex) if cells.dtype.kind in "fiuc"   # numbers: at once
                  else np.array([_parse_complex(v) for v in cells], dtype=complex))
    except (TypeError, ValueError):
        raise ContractError(f"{source}: column {col!r} holds a value that is not a number") from None
    if np.isinf(values).any():
        row = int(np.flatnonzero(np.isinf(values))[0])
        raise ContractError(f"{source}: row {row + 2}: column {col!r} holds an infinite value")
    written = np.array([isinstance(v, str) for v in cells], bool) if cells.dtype == object \
        else np.zeros(cells.size, bool)   # an empty cell is NaN
    half = written & (np.isnan(values.real) != np.isnan(values.imag))   # 'nan+1j': neither
    if half.any():
        row = int(np.flatnonzero(half)[0])
        raise ContractError(f"{source}: row {row + 2}: column {col!r} holds {cells[row]!r}, a "
                            "complex number with one part NaN (leave the cell empty for no value)")
    if (np.abs(values) > MAX_MAGNITUDE).any():
        row = int(np.flatnonzero(np.abs(values) > MAX_MAGNITUDE)[0])
        shown = values[row].real if values[row].imag == 0 else values[row]
        raise ContractError(f"{source}: row {row + 2}: column {col!r} holds {shown:g}, above "
                            f"{MAX_MAGNITUDE:g} in magnitude")
    values = np.where(np.abs(values.real) < TINIEST, 0.0, values.real) + 1j * np.where(
        np.abs(values.imag) < TINIEST, 0.0, values.imag)   # subnormal parts are 0
    return values.real if np.all(values.imag == 0) else values


def _real_shapes(columns: Sequence[str], cells: np.ndarray,
                 source: str) -> tuple[np.ndarray, tuple[int, str] | None]:
    """Shape ``columns`` whose cells are numbers, all at once: ``cells`` [n_rows, n_columns] as floats
    (subnormal values 0), and the position and message of their first column holding an infinite value
    or one above :data:`MAX_MAGNITUDE` in magnitude (None when none does), worded as
    :func:`_shape_values` words it."""
    values = cells.astype(float)
    infinite = np.isinf(values)
    huge = ~infinite & (np.abs(values) > MAX_MAGNITUDE)
    bad = (infinite | huge).any(axis=0)
    if not bad.any():
        return np.where(np.abs(values) < TINIEST, 0.0, values), None
    k = int(np.argmax(bad))
    if infinite[:, k].any():
        row = int(np.argmax(infinite[:, k]))
        return values, (k, f"{source}: row {row + 2}: column {columns[k]!r} holds an infinite value")
    row = int(np.argmax(huge[:, k]))
    return values, (k, f"{source}: row {row + 2}: column {columns[k]!r} holds {values[row, k]:g}, above "
                       f"{MAX_MAGNITUDE:g} in magnitude")


def _shape_frame(df: pd.DataFrame, columns: list[str], source: str) -> pd.DataFrame:
    """The shape ``columns`` of ``df`` as a frame of floats (complex where a column has an imaginary
    part): the columns of numbers as one block (a column at a time cost 0.1 ms of numpy and pandas each,
    a second for a laser scan's 10,000 sensors), the others (text such as ``0.1+0.2j``) one by one.  The
    first column in table order that is not valid raises ContractError (:func:`_shape_values`), then a
    mode shape that is not all zero but below :data:`MIN_PEAK` (:func:`_shapes_in_range`)."""
    position = {c: k for k, c in enumerate(columns)}
    kinds = df.dtypes[columns].map(lambda t: t.kind).to_numpy()
    real = [c for c, kind in zip(columns, kinds, strict=True) if kind in "fiu"]
    block, fault = _real_shapes(real, df[real].to_numpy(dtype=float, na_value=np.nan), source)   # NA: NaN
    first_bad = position[real[fault[0]]] if fault else len(columns)
    others = {}
    for col in [c for c, kind in zip(columns, kinds, strict=True) if kind not in "fiu"]:   # text columns
        if position[col] > first_bad:
            break
        others[col] = _shape_values(col, df[col].to_numpy(), source)
    if fault:
        raise ContractError(fault[1])
    peak = np.fmax.reduce(np.abs(block), axis=1, initial=0.0)   # NaN (no value) is passed over
    for values in others.values():
        peak = np.fmax(peak, np.abs(values))
    _shapes_in_range(peak, columns, source)
    numbers = pd.DataFrame(block, index=df.index, columns=real)
    return pd.concat([numbers, pd.DataFrame(others, index=df.index)], axis=1)[columns] if others else numbers


def _shapes_in_range(peak: np.ndarray, columns: Sequence[str], source: str) -> None:
    """Raise ContractError naming the first row (header = row 1) whose mode shape, whose largest
    magnitude over the shape ``columns`` is ``peak`` (per row), is not all zero but at most
    :data:`MIN_PEAK` in magnitude: as for measured data (checked_io.data_range), its squares underflow
    to 0, and every shape comparison (MAC, COMAC, the diagnosis' shape misfit) would read it as a shape
    without motion."""
    tiny = (peak > 0) & (peak < MIN_PEAK)
    if tiny.any():
        row = int(np.flatnonzero(tiny)[0])
        named = ", ".join(columns) if len(columns) <= 3 else f"{columns[0]} .. {columns[-1]}"
        raise ContractError(f"{source}: row {row + 2}: the mode shape ({named}) is at most {peak[row]:.4g} "
                            f"in magnitude, below {MIN_PEAK:g} (its squares underflow to 0: is the unit "
                            "right?)")


@dataclass(frozen=True)
class ModalTable:
    """A validated modal table; ``frame`` is sorted by config then mode and must not be mutated."""

    frame: pd.DataFrame
    source: str = "<table>"

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_frame(cls, frame: pd.DataFrame, source: str = "<table>") -> ModalTable:
        """Validate a DataFrame with the contract's columns (raises ContractError naming the problem)."""
        df = frame.copy()
        for col in REQUIRED:
            if col not in df.columns:
                raise ContractError(f"{source}: missing required column {col!r}")
        df["config"] = df["config"].astype(str)
        unnamed = [c for c in df.columns if str(c) in (POSE_PREFIX, SHAPE_PREFIX)]
        if unnamed:
            raise ContractError(f"{source}: column {unnamed[0]!r} names no "
                                f"{'pose variable' if unnamed[0] == POSE_PREFIX else 'sensor'} after the dot")
        _check_names(df, source)
        for col in ("mode", "freq_hz"):
            values = _floats(df[col])
            bad = values.isna() | ~np.isfinite(values)
            if bad.any():
                row = int(np.flatnonzero(bad.to_numpy())[0])
                shown = df[col].iloc[row]
                if isinstance(shown, bool | np.bool_):
                    shown = bool(shown)
                elif not isinstance(shown, str):   # pandas' NA (a nullable Int64 or Float64 column) as NaN
                    shown = float(shown) if pd.notna(shown) else float("nan")
                raise ContractError(f"{source}: row {row + 2}: column {col!r} is not a number ({shown!r})")
            df[col] = values
        df["freq_hz"] = _numbers(df["freq_hz"], "freq_hz", source, MAX_FREQ_HZ)
        if (df["mode"] < 1).any():
            raise ContractError(f"{source}: column 'mode' must be 1-based (found {df['mode'].min():g})")
        odd = (df["mode"] != np.round(df["mode"])) | (df["mode"] > MAX_MODE)
        if odd.any():
            row = int(np.flatnonzero(odd.to_numpy())[0])
            raise ContractError(f"{source}: row {row + 2}: mode = {df['mode'].iloc[row]:g} is not a whole "
                                f"number from 1 to {MAX_MODE:g}")
        df["mode"] = df["mode"].astype(int)
        if (df["freq_hz"] <= 0).any():
            row = int(np.flatnonzero((df["freq_hz"] <= 0).to_numpy())[0])
            raise ContractError(f"{source}: row {row + 2}: freq_hz = {df['freq_hz'].iloc[row]:g} is not "
                                "above 0 Hz (a rigid-body mode: leave it out)")
        dup = df[["config", "mode"]].duplicated()   # not df.duplicated(subset): it walks every column
        if dup.any():
            r = df[dup].iloc[0]
            raise ContractError(f"{source}: config {r['config']!r} lists mode {int(r['mode'])} twice")
        if MAP_COLUMN not in df.columns:   # a modal map follows each mode along the pose, across others
            _rising_frequencies(df, source)
        numeric = ("damping_ratio", *STD_COLUMNS)
        for col in [c for c in df.columns if c in numeric or c.startswith(POSE_PREFIX)]:
            limit = MAX_POSE if col.startswith(POSE_PREFIX) else MAX_MAGNITUDE
            df[col] = _numbers(df[col], col, source, limit)
        if MAP_COLUMN not in df.columns:   # a modal map's pose is each row's mean within its pose bin
            _one_pose_per_config(df, source)
        for col in [c for c in STD_COLUMNS if c in df.columns and (df[c] < 0).any()]:
            row = int(np.flatnonzero((df[col] < 0).to_numpy())[0])
            raise ContractError(f"{source}: row {row + 2}: {col} = {df[col].iloc[row]:g} is negative (a "
                                "standard deviation)")
        if "damping_ratio" in df.columns and (df["damping_ratio"] <= -1).any():
            row = int(np.flatnonzero((df["damping_ratio"] <= -1).to_numpy())[0])
            raise ContractError(f"{source}: row {row + 2}: damping_ratio = {df['damping_ratio'].iloc[row]:g} "
                                "is not above -1 (a fraction; negative: a growing mode)")
        if "damping_ratio" in df.columns and (df["damping_ratio"] >= 1).any():
            row = int(np.flatnonzero((df["damping_ratio"] >= 1).to_numpy())[0])
            value = df["damping_ratio"].iloc[row]
            raise ContractError(f"{source}: row {row + 2}: damping_ratio = {value:g} is not below 1 (a "
                                f"fraction: {value:g} % is {value / 100:g})")
        columns = [c for c in df.columns if c.startswith(SHAPE_PREFIX)]
        if columns:   # taken out and put back at once: pandas copies its block at every column set
            df = pd.concat([df.drop(columns=columns), _shape_frame(df, columns, source)],
                           axis=1)[list(df.columns)]
        rank = {c: k for k, c in enumerate(natural_order(df["config"]))}   # theta30 before theta120
        df = df.sort_values(["config", "mode"], kind="stable", key=lambda col: col.map(rank)
                            if col.name == "config" else col).reset_index(drop=True)
        return cls(df, source)

    @classmethod
    def from_records(cls, records: Iterable[Mapping[str, object]], source: str = "<table>") -> ModalTable:
        return cls.from_frame(pd.DataFrame(list(records)), source)

    @classmethod
    def read_csv(cls, path: str | Path) -> ModalTable:
        df = read_table(path, ContractError, required=REQUIRED, text_columns=("config",), what="modal table")
        if df.empty:
            raise ContractError(f"{path}: the modal table has a header but no rows (no mode to read)")
        return cls.from_frame(df, str(path))

    def to_csv(self, path: str | Path) -> None:
        """Write CSV (whole or not at all, checked_io.output.atomic_path); complex shapes as ``a+bj`` text,
        floats with full precision."""
        df = self.frame.copy()
        for col in self.shape_columns:
            if np.iscomplexobj(df[col].to_numpy()):
                df[col] = [f"{v.real:.9g}{v.imag:+.9g}j" for v in df[col].to_numpy()]
        with atomic_path(path) as tmp:
            df.to_csv(tmp, index=False, float_format="%.9g")

    # -- views (each configuration's rows are found once, so a view costs no scan of the table) ----
    @cached_property
    def _rows_of(self) -> dict[str, np.ndarray]:
        """Row positions of every configuration, configurations in order of first appearance."""
        codes, names = pd.factorize(self.frame["config"], sort=False)
        if not len(names):  # a table without rows (np.split would still hand out one empty part)
            return {}
        order = np.argsort(codes, kind="stable")
        bounds = np.cumsum(np.bincount(codes, minlength=len(names)))[:-1]
        return {str(n): rows for n, rows in zip(names, np.split(order, bounds), strict=True)}

    @cached_property
    def _columns(self) -> dict[str, np.ndarray]:
        """Every column as a numpy array (read once)."""
        return {c: self.frame[c].to_numpy() for c in self.frame.columns}

    @property
    def configs(self) -> list[str]:
        """Configuration ids in order of first appearance."""
        return list(self._rows_of)

    @cached_property
    def _prefixed(self) -> dict[str, tuple[str, ...]]:
        """The pose and the shape columns (by prefix), in table order: found once, not at every call."""
        columns = self.frame.columns
        return {p: tuple(c for c in columns if c.startswith(p)) for p in (POSE_PREFIX, SHAPE_PREFIX)}

    @property
    def pose_columns(self) -> list[str]:
        return list(self._prefixed[POSE_PREFIX])

    @property
    def shape_columns(self) -> list[str]:
        return list(self._prefixed[SHAPE_PREFIX])

    @property
    def sensors(self) -> list[str]:
        return [c[len(SHAPE_PREFIX):] for c in self._prefixed[SHAPE_PREFIX]]

    def has_config(self, config: str) -> bool:
        return config in self._rows_of

    def _positions(self, config: str) -> np.ndarray:
        return self._rows_of.get(config, np.zeros(0, int))

    def rows(self, config: str) -> pd.DataFrame:
        return self.frame.iloc[self._positions(config)]

    def column(self, config: str, name: str) -> np.ndarray:
        """Values of column ``name`` on the rows of ``config`` (in table order)."""
        return self._columns[name][self._positions(config)]

    def freq_hz(self, config: str) -> np.ndarray:
        return self.column(config, "freq_hz").astype(float)

    def pose(self, config: str) -> dict[str, float]:
        """Pose of a configuration as {variable: value} without the ``pose.`` prefix."""
        first = self._positions(config)[:1]
        if not first.size:
            raise KeyError(config)
        return {c[len(POSE_PREFIX):]: v for c in self.pose_columns
                if pd.notna(v := self._columns[c][first[0]])}

    def shapes(self, config: str, sensors: Sequence[str] | None = None) -> np.ndarray:
        """Mode shapes [n_sensors, n_modes] of one configuration (NaN where absent)."""
        cols = [SHAPE_PREFIX + s for s in (sensors if sensors is not None else self.sensors)]
        at = self._positions(config)
        return np.array([self._columns[c][at] if c in self._columns else np.full(at.size, np.nan)
                         for c in cols]).reshape(len(cols), at.size)


    # -- notebook display (Jupyter shows _repr_html_, print and the REPL __repr__) --------------------
    def to_frame(self) -> pd.DataFrame:
        """A copy of the table as a DataFrame, one row per mode, with the contract's columns and units in
        their names (docs/formats.md): ``config``, ``mode``, ``freq_hz`` [Hz], ``damping_ratio`` [-],
        ``pose.<var>``, ``shape.<sensor>``."""
        return self.frame.copy()

    def __repr__(self) -> str:
        f = self.frame["freq_hz"].to_numpy(float)
        span = f"{f.min():.4g}-{f.max():.4g} Hz" if f.size else "no modes"
        return (f"ModalTable({self.source!r}: {len(self.configs)} configurations, {len(self.frame)} modes, "
                f"{span}, shapes at {len(self.sensors)} sensors)")

    def _repr_html_(self) -> str:
        df = self.frame
        shown = pd.DataFrame({"config": df["config"], **{c: df[c] for c in self.pose_columns},
                              "mode": df["mode"], "f [Hz]": df["freq_hz"].map("{:.2f}".format)})
        if "damping_ratio" in df:
            shown["ζ [%]"] = (100 * df["damping_ratio"]).map(lambda z: f"{z:.2f}" if pd.notna(z) else "")
        note = f"; shapes at {', '.join(self.sensors)} in <code>to_frame()</code>" if self.sensors else ""
        return display_html(f"Modal table <b>{html.escape(self.source)}</b>: {len(self.configs)} "
                            f"configurations, {len(df)} modes{note}", shown)


def display_html(summary: str, frame: pd.DataFrame, max_rows: int = 30) -> str:
    """A notebook display: one line of ``summary`` (HTML) over ``frame`` as an HTML table (at most
    ``max_rows`` rows, pandas elides the middle of longer ones)."""
    return f"<p>{summary}</p>" + frame.to_html(index=False, max_rows=max_rows, escape=True, border=0)


def _check_names(df: pd.DataFrame, source: str) -> None:
    """Raise ContractError for a configuration, sensor or pose variable whose name is blank or holds
    a control character (checked_io.text.name_fault): 'theta\\n0' would break every one-line message
    and table row it is printed in, and '   ' names nothing; and for two pose variables whose names
    differ only by case."""
    prefixes = (POSE_PREFIX, SHAPE_PREFIX)
    named = [(f"config {c!r}", c) for c in pd.unique(df["config"])]
    named += [(f"column {c!r}", c.split(".", 1)[1]) for c in map(str, df.columns) if c.startswith(prefixes)]
    if "source" in df.columns:   # a source is a column title of every comparison table
        named += [(f"source {s!r}", s) for s in pd.unique(df["source"].dropna().astype(str))]
    for what, name in named:
        fault = name_fault(name)
        if fault:
            raise ContractError(f"{source}: {what}: the name {fault}")
    poses = [c for c in map(str, df.columns) if c.startswith(POSE_PREFIX)]
    folded = [c.casefold() for c in poses]
    twice = [c for c, f in zip(poses, folded, strict=True) if folded.count(f) > 1]
    if twice:   # pose.theta_deg and pose.Theta_deg were two variables of one pose
        raise ContractError(f"{source}: columns {twice[0]!r} and {twice[1]!r} differ only by case: one pose "
                            "variable given twice, or two that a reader cannot tell apart (rename one)")


def _rising_frequencies(df: pd.DataFrame, source: str) -> None:
    """Raise ContractError naming the first row whose mode has a lower ``freq_hz`` than the mode numbered
    before it in its configuration (docs/formats.md: modes are numbered in order of rising frequency;
    equal frequencies, a repeated mode, pass).  Rows are counted as in the CSV (header line 1)."""
    order = np.lexsort((df["mode"].to_numpy(), pd.factorize(df["config"])[0]))
    config, mode, freq = (df[c].to_numpy()[order] for c in ("config", "mode", "freq_hz"))
    falls = (config[1:] == config[:-1]) & (freq[1:] < freq[:-1])
    if falls.any():
        k = int(np.argmax(falls))
        row, before = order[k + 1] + 2, order[k] + 2
        raise ContractError(f"{source}: row {row}: freq_hz = {freq[k + 1]:g} of mode {mode[k + 1]} is below "
                            f"the {freq[k]:g} Hz of mode {mode[k]} (row {before}) in config {config[k]!r}: "
                            "modes are numbered in order of rising frequency")


def _one_pose_per_config(df: pd.DataFrame, source: str) -> None:
    """Raise ContractError when two rows of one configuration give one pose variable different values
    (the pose of a configuration is one pose; otherwise whichever row came first would silently win).
    Not applied to a modal map (its :data:`MAP_COLUMN`): there a configuration is a pose bin and each
    row carries the mean pose of the windows behind that mode (docs/oma.md)."""
    for col in [c for c in df.columns if c.startswith(POSE_PREFIX)]:
        values = df.groupby("config", sort=False)[col]
        split = values.nunique(dropna=True) > 1
        if split.any():
            config = split.index[int(np.argmax(split.to_numpy()))]
            seen = df.loc[df["config"] == config, col].dropna().unique()[:2]
            raise ContractError(f"{source}: config {config!r} has two values of {col} ({seen[0]:g} and "
                                f"{seen[1]:g}): a configuration is one pose (give each pose its own config)")


def poses_from_csv(path: str | Path) -> dict[str, dict[str, float]]:
    """Read POSES.csv (docs/formats.md without mode/freq_hz): {config: {pose variable: value}}."""
    p = Path(path)
    df = read_table(p, ContractError, required=("config",), text_columns=("config",), what="poses table")
    cols = [c for c in df.columns if c.startswith(POSE_PREFIX)]
    _check_names(df.assign(config=df["config"].astype(str)), str(p))
    out: dict[str, dict[str, float]] = {}
    for _, row in df.iterrows():
        pose = {}
        for c in cols:
            value = pd.to_numeric(row[c], errors="coerce")
            if pd.isna(value) or not np.isfinite(value):
                what = "is not a number" if pd.isna(value) else "is not finite"
                raise ContractError(f"{p}: config {row['config']!r}: {c} {what} ({row[c]!r})")
            if abs(value) > MAX_POSE:   # as in a modal table: it was named in the predictions, not here
                raise ContractError(f"{p}: config {row['config']!r}: {c} = {value:g} is above "
                                    f"{MAX_POSE:g} in magnitude")
            pose[c[len(POSE_PREFIX):]] = float(value)
        out[str(row["config"])] = pose
    if MAP_COLUMN not in df.columns:
        _one_pose_per_config(df.assign(**{c: pd.to_numeric(df[c]) for c in cols}), str(p))
    return out
