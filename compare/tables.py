"""Comparison tables of measured and predicted modes (the layouts of seed 001 Table 3.1 and seed 000 Table 2).

``compare_tables`` pairs every predicted source with the measured table (compare.pairing) and
``render`` writes the result as Markdown, CSV, LaTeX (booktabs) or an HTML table.  Two layouts:

* ``modes`` (Table 3.1): a row per measured mode (per configuration), columns the predicted sources'
  frequencies [Hz], the experiment [Hz], the measured damping ratio ζ [%], each source's error
  Δf = (f_pred - f_meas) / f_meas [%] and, where pairing used shapes, its MAC.  Predicted modes that
  pair with no measured mode get rows of their own with the experiment cells empty.
* ``sources`` (Table 2): a row per source (experiment, ζ and errors included), a column per mode.

Units sit in every header: f [Hz], ζ [%], Δf [%], MAC [-] (dimensionless, 0..1).  Modes that stay
unpaired are listed in the notes under the table (and as rows in the ``modes`` layout).
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from flexmodal.checked_io.plural import counted
from flexmodal.checked_io.text import natural_key
from flexmodal.compare.errors import CompareError
from flexmodal.compare.pairing import MIN_MAC, WHY_NOT_MAC, ModeRef, Pair, Pairing, pair_modes
from flexmodal.contract.table import ModalTable

FORMATS = ("md", "csv", "tex", "html", "json")
LAYOUTS = ("modes", "sources")

# per format: how each quantity is labelled (the unit is part of the label)
_LABELS = {
    "md": {"f": "f [Hz]", "zeta": "ζ [%]", "err": "Δf [%]", "mac": "MAC [-]", "mode": "mode",
           "pmode": "mode"},
    "html": {"f": "f [Hz]", "zeta": "ζ [%]", "err": "Δf [%]", "mac": "MAC [-]", "mode": "mode",
             "pmode": "mode"},
    "tex": {"f": "$f$ [Hz]", "zeta": r"$\zeta$ [\%]", "err": r"$\Delta f$ [\%]", "mac": "MAC [--]",
            "mode": "mode", "pmode": "mode"},
    "csv": {"f": "freq_hz", "zeta": "damping_pct", "err": "err_pct", "mac": "mac", "mode": "mode",
            "pmode": "mode"},
}
_DIGITS = {"f": "{:.2f}", "zeta": "{:.2f}", "err": "{:+.1f}", "mac": "{:.3f}", "mode": "{:d}",
           "pmode": "{:d}"}


@dataclass(frozen=True)
class Comparison:
    """A measured table and the pairing of every predicted source against it."""

    measured_name: str
    measured: ModalTable
    predictions: tuple[tuple[str, ModalTable], ...]
    pairings: tuple[Pairing, ...]

    @cached_property
    def configs(self) -> list[str]:
        """Measured configurations in pose order (``ordered_configs``), then those only predicted."""
        configs = ordered_configs(self.measured)
        seen = set(configs)
        for (_, table), p in zip(self.predictions, self.pairings, strict=True):
            lone = {r.config for r in p.unpaired_predicted}
            for c in ordered_configs(table):
                if c in lone and c not in seen:
                    configs.append(c)
                    seen.add(c)
        return configs

    @cached_property
    def _by_config(self) -> list[dict[str, tuple[list[ModeRef], list[ModeRef], list[Pair]]]]:
        """Per pairing: config -> (unpaired measured, unpaired predicted, pairs), grouped once."""
        out = []
        for p in self.pairings:
            groups: dict[str, tuple[list[ModeRef], list[ModeRef], list[Pair]]] = {}
            for r in p.unpaired_measured:
                groups.setdefault(r.config, ([], [], []))[0].append(r)
            for r in p.unpaired_predicted:
                groups.setdefault(r.config, ([], [], []))[1].append(r)
            for q in p.pairs:
                groups.setdefault(q.measured.config, ([], [], []))[2].append(q)
            out.append(groups)
        return out

    def _of(self, k: int, config: str) -> tuple[list[ModeRef], list[ModeRef], list[Pair]]:
        """Pairing ``k``'s unpaired measured, unpaired predicted modes and pairs of ``config``."""
        return self._by_config[k].get(config, ([], [], []))

    @cached_property
    def has_damping(self) -> bool:
        df = self.measured.frame
        return "damping_ratio" in df and bool(np.isfinite(df["damping_ratio"].to_numpy(float)).any())

    # -- notebook display: to_frame, __repr__, _repr_html_ ------------------------------------------
    def to_frame(self, layout: str = "modes"):
        """The comparison as a pandas DataFrame of full-precision numbers with units in the headers
        (``fe f [Hz]``, ``experiment ζ [%]``, ``fe Δf [%]``, ``fe MAC [-]``): a row per measured mode
        (``layout="modes"``) or per source and quantity (``"sources"``), as :func:`render` lays it out."""
        import pandas as pd

        cols, rows = _modes_grid(self) if layout == "modes" else _sources_grid(self)
        return pd.DataFrame([[_plain(c.quantity, v) for c, v in zip(cols, row, strict=True)] for row in rows],
                            columns=[_header(c, "md") for c in cols])

    def __repr__(self) -> str:
        parts = []
        for p in self.pairings:
            err = [q.rel_error for q in p.pairs]
            rms = f", RMS Δf {100 * math.sqrt(sum(e * e for e in err) / len(err)):.3g} %" if err else ""
            parts.append(f"{p.source}: {len(p.pairs)} paired{rms}")
        return (f"Comparison({self.measured_name}: {len(self.configs)} configurations, "
                f"{len(self.measured.frame)} measured modes; {'; '.join(parts)})")

    def _repr_html_(self) -> str:
        return html_fragment(self)

    def notes(self) -> list[str]:
        """One line per unpaired mode, naming source, configuration, mode and frequency [Hz], and one per
        configuration whose shapes could not be compared (compare.pairing.WHY_NOT_MAC says why)."""
        out = []
        unused = [dict(p.shapes_unused) for p in self.pairings]
        for config in self.configs:
            for k, p in enumerate(self.pairings):
                if config in unused[k]:
                    out.append(f"{p.source}: {config}: {WHY_NOT_MAC[unused[k][config]]}: paired by frequency "
                               "order, not by MAC")
                lone_meas, lone_pred, _ = self._of(k, config)
                out += [f"{p.source}: no predicted mode pairs with measured mode {r.mode} of "
                        f"{r.config} ({r.freq_hz:.2f} Hz)" for r in lone_meas]
                out += [f"{p.source}: mode {r.mode} of {r.config} ({r.freq_hz:.2f} Hz) pairs with no "
                        f"measured mode" for r in lone_pred]
        return out

    def warnings(self) -> list[str]:
        """One line per predicted source and reason why shapes both tables give could not pair modes by
        MAC (:func:`shape_warnings`): the modes were paired by frequency order instead, which the CSV and
        JSON formats do not show."""
        return [line for (_, table), p in zip(self.predictions, self.pairings, strict=True)
                for line in shape_warnings(p.source, p.shapes_unused, (self.measured, table))]


def shape_warnings(source: str, unused: Sequence[tuple[str, str]],
                   tables: Sequence[ModalTable]) -> list[str]:
    """One line per reason in ``unused`` ((configuration, key of compare.pairing.WHY_NOT_MAC) whose modes
    were paired by frequency order, not by MAC), starting with ``source`` (the predicted table's, or the
    rig's for a diagnosis), naming the configurations and the file(s) and shape columns to blame:
    ``tables`` (measured, predicted) or (measured,); a zero side names its own table, other reasons all.

    Examples
    --------
    >>> table = ModalTable.from_records([{"config": c, "mode": 1, "freq_hz": 9.0, "shape.a1": 0.0,
    ...                                   "shape.a2": 0.0} for c in "pqrst"], "modes.csv")
    >>> print(*shape_warnings("rig.toml", [(c, "zero measured") for c in table.configs], [table]))
    rig.toml: every measured mode shape is zero at the common sensors (MAC undefined) in 5 configurations
    (p, q, r and 2 more) of modes.csv (shape.a1, shape.a2): paired by frequency order, not by MAC
    """
    configs: dict[str, list[str]] = {}
    for config, why in unused:
        configs.setdefault(why, []).append(config)
    sides = {"zero measured": tables[:1], "zero predicted": tables[-1:]}
    out = []
    for why, where in configs.items():
        named = " and ".join(f"{t.source} ({_shape_columns(t)})" for t in sides.get(why, tables))
        shown = ", ".join(where[:3]) + (f" and {len(where) - 3} more" if len(where) > 3 else "")
        out.append(f"{source}: {WHY_NOT_MAC[why]} in {counted(len(where), 'configuration')} ({shown}) of "
                   f"{named}: paired by frequency order, not by MAC")
    return out


def _shape_columns(table: ModalTable) -> str:
    """The shape columns of ``table`` for a message: all of up to three, else the first, the last and
    their count."""
    cols = table.shape_columns
    return ", ".join(cols) if len(cols) <= 3 else f"{cols[0]} .. {cols[-1]}, {len(cols)} columns"


def ordered_configs(table: ModalTable) -> list[str]:
    """Configurations sorted by their numeric pose values (in column order), then naturally by name
    (``theta60`` before ``theta120``)."""
    df = table.frame
    cols = [c for c in table.pose_columns if df[c].dtype.kind in "fi"]
    first = df.groupby("config", sort=False)[cols].first() if cols else None
    poses = {} if first is None else dict(zip(first.index, np.nan_to_num(
        first.to_numpy(float), nan=math.inf, posinf=math.inf).tolist(), strict=True))

    def key(config: str) -> tuple:
        return tuple(poses.get(config, ())), natural_key(config)

    return sorted(table.configs, key=key)


def table_name(table: ModalTable, fallback: str) -> str:
    """The table's single ``source`` column value, else ``fallback`` (e.g. the file stem)."""
    if "source" in table.frame:
        values = table.frame["source"].dropna().astype(str).unique()
        if len(values) == 1 and values[0].strip():
            return str(values[0])
    return fallback


def compare_tables(measured: ModalTable, predictions: Sequence[tuple[str, ModalTable]], *,
                   measured_name: str = "experiment", min_mac: float = MIN_MAC) -> Comparison:
    """Pair each (name, predicted table) with ``measured``; repeated names get a ``#2``, ``#3`` suffix."""
    if not predictions:
        raise CompareError("compare needs at least one predicted modal table")
    named: list[tuple[str, ModalTable]] = []
    seen: dict[str, int] = {measured_name: 1}
    for name, table in predictions:
        seen[name] = seen.get(name, 0) + 1
        named.append((name if seen[name] == 1 else f"{name}#{seen[name]}", table))
    pairings = tuple(pair_modes(measured, t, n, min_mac=min_mac) for n, t in named)
    return Comparison(measured_name, measured, tuple(named), pairings)


# ---------------------------------------------------------------------------------------------
# the grid: header cells (source, quantity) and rows of (quantity, value) cells


@dataclass(frozen=True)
class _Col:
    source: str  # "" for config / mode columns
    quantity: str  # config | mode | f | zeta | err | mac


def _modes_grid(comp: Comparison) -> tuple[list[_Col], list[list[object]]]:
    multi = len(comp.configs) > 1
    cols = ([_Col("", "config")] if multi else []) + [_Col("", "mode")]
    cols += [_Col(name, "f") for name, _ in comp.predictions]
    cols += [_Col(comp.measured_name, "f")] + ([_Col(comp.measured_name, "zeta")] if comp.has_damping else [])
    cols += [_Col(name, "err") for name, _ in comp.predictions]
    cols += [_Col(p.source, "mac") for p in comp.pairings if any(q.method == "mac" for q in p.pairs)]
    cols += [_Col(p.source, "pmode") for p in comp.pairings
             if any(q.predicted.mode != q.measured.mode for q in p.pairs) or p.unpaired_predicted]
    meas = comp.measured
    rows: list[list[object]] = []
    for config in comp.configs:
        zetas = meas.column(config, "damping_ratio") if comp.has_damping else None
        for i, (mode, freq) in enumerate(zip(meas.column(config, "mode"), meas.column(config, "freq_hz"),
                                             strict=True)):
            cells: dict[tuple[str, str], object] = {("", "config"): config, ("", "mode"): int(mode),
                                                    (comp.measured_name, "f"): float(freq)}
            if zetas is not None:
                cells[(comp.measured_name, "zeta")] = 100.0 * float(zetas[i])
            for p in comp.pairings:
                pair = p.pair_of(config, int(mode))
                if pair is not None:
                    cells[(p.source, "f")] = pair.predicted.freq_hz
                    cells[(p.source, "err")] = 100.0 * pair.rel_error
                    cells[(p.source, "mac")] = pair.mac
                    cells[(p.source, "pmode")] = pair.predicted.mode
            rows.append([cells.get((c.source, c.quantity)) for c in cols])
        extra: dict[int, dict[tuple[str, str], object]] = {}  # unpaired predicted modes by mode number
        for k, p in enumerate(comp.pairings):
            for r in comp._of(k, config)[1]:
                cells = extra.setdefault(r.mode, {("", "config"): config})
                cells[(p.source, "f")], cells[(p.source, "pmode")] = r.freq_hz, r.mode
        rows += [[cells.get((c.source, c.quantity)) for c in cols] for _, cells in sorted(extra.items())]
    return cols, rows


def _sources_grid(comp: Comparison) -> tuple[list[_Col], list[list[object]]]:
    meas = comp.measured.frame
    modes = sorted(int(m) for m in meas["mode"].unique())
    multi = len(comp.configs) > 1
    cols = ([_Col("", "config")] if multi else []) + [_Col("", "source"), _Col("", "quantity")]
    cols += [_Col(f"mode {m}", "cell") for m in modes]
    rows: list[list[object]] = []
    table = comp.measured
    for config in [c for c in comp.configs if table.has_config(c)]:
        mode_of = [int(m) for m in table.column(config, "mode")]
        lines: list[tuple[str, str, dict[int, float]]] = []
        for k, p in enumerate(comp.pairings):
            pairs = comp._of(k, config)[2]
            lines.append((p.source, "f", {q.measured.mode: q.predicted.freq_hz for q in pairs}))
        lines.append((comp.measured_name, "f", dict(zip(mode_of, table.freq_hz(config), strict=True))))
        if comp.has_damping:
            zeta = 100.0 * table.column(config, "damping_ratio").astype(float)
            lines.append((comp.measured_name, "zeta", dict(zip(mode_of, zeta, strict=True))))
        for k, p in enumerate(comp.pairings):
            pairs = comp._of(k, config)[2]
            lines.append((p.source, "err", {q.measured.mode: 100.0 * q.rel_error for q in pairs}))
        for source, quantity, values in lines:
            head: list[object] = ([config] if multi else []) + [source, quantity]
            rows.append(head + [(quantity, values.get(m)) for m in modes])
    return cols, rows


def _plain(quantity: str, value: object) -> object:
    """A cell as a plain value for data formats: full-precision float, int mode, text, or None."""
    if isinstance(value, tuple):  # (quantity, value) cell of the sources layout
        return _plain(*value)
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return None
    if quantity in _DIGITS and not isinstance(value, str):
        return int(value) if quantity.endswith("mode") else float(value)
    return str(value)


def _fmt(quantity: str, value: object, full: bool = False) -> str:
    """A cell as text: rounded for display (md, tex, html) or, ``full``, the shortest repr that
    round-trips the float exactly (csv)."""
    if isinstance(value, tuple):
        return _fmt(*value, full=full)
    plain = _plain(quantity, value)
    if plain is None:
        return ""
    if quantity in _DIGITS and not isinstance(plain, str):
        return repr(plain) if full else _DIGITS[quantity].format(plain)
    return plain


def _header(col: _Col, fmt: str) -> str:
    """Header text, already safe for ``fmt`` (LaTeX-escaped for tex)."""
    labels = _LABELS[fmt]
    esc = _escape(fmt)
    if col.quantity in ("config", "source", "quantity"):
        return col.quantity
    if col.quantity == "cell":
        return esc(col.source) + {"csv": "", "tex": r" [Hz, \%]"}.get(fmt, " [Hz, %]")
    if not col.source:
        return labels[col.quantity]
    if fmt == "csv":
        return f"{col.source}_{labels[col.quantity]}"
    return f"{esc(col.source)} {labels[col.quantity]}"


def _cells(cols: list[_Col], rows: list[list[object]], fmt: str) -> list[list[str]]:
    """Body text, already safe for ``fmt`` (LaTeX-escaped for tex)."""
    labels = _LABELS[fmt]
    esc = _escape(fmt)
    return [[labels[str(v)] if c.quantity == "quantity" else esc(_fmt(c.quantity, v, full=fmt == "csv"))
             for c, v in zip(cols, row, strict=True)] for row in rows]


# ---------------------------------------------------------------------------------------------
# renderers


_TEX = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "_": r"\_", "#": r"\#", "$": r"\$", "{": r"\{",
        "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "<": r"\textless{}",
        ">": r"\textgreater{}", "|": r"\textbar{}", "ζ": r"$\zeta$", "Δ": r"$\Delta$", "\n": " ", "\r": " "}
_TEX_SPECIAL = re.compile("|".join(re.escape(k) for k in _TEX))


def _tex_escape(text: str) -> str:
    r"""``text`` safe in LaTeX: each special character replaced in one pass (so the braces of
    ``\textbackslash{}`` are not escaped again); a line break is a space (it would end the row).

    Examples
    --------
    >>> print(_tex_escape("x_1 & $5 {a}~^ 50% #2 \\ Δf"))
    x\_1 \& \$5 \{a\}\textasciitilde{}\textasciicircum{} 50\% \#2 \textbackslash{} $\Delta$f
    >>> print(_tex_escape("<b>|"))
    \textless{}b\textgreater{}\textbar{}

    (``<``, ``>`` and ``|`` are other glyphs, ¡ ¿ —, in LaTeX's default OT1 text font.)
    """
    return _TEX_SPECIAL.sub(lambda m: _TEX[m.group(0)], text)


_MD_SPECIAL = re.compile(r"[\\`*<>&~|]|\](?=[(:\[])|(?<![^\W_])_|_(?![^\W_])")   # theta_deg: no emphasis
_MD_LINE_START = re.compile(r"^([-+=#>]|\d+(?=[.)]))")


def _md_escape(text: str, line_start: bool = False) -> str:
    r"""``text`` shown as it is in a Markdown table cell or list item (CommonMark): each character that
    could start markup (emphasis, code, an HTML tag or entity, a cell border; the ``]`` that would close
    a link or a link definition) backslash-escaped, a line break a space; text that starts a line or a
    list item (``line_start``) has a leading list, heading or quote marker escaped too.

    Examples
    --------
    >>> print(_md_escape("a|b\nc <b>x_1</b> [l](u) &amp; _e_"))
    a\|b c \<b\>x_1\</b\> [l\](u) \&amp; \_e\_
    >>> print(_md_escape("- 1. f [Hz]", line_start=True), _md_escape("12) #2", line_start=True))
    \- 1. f [Hz] 12\) #2
    """
    flat = _MD_SPECIAL.sub(lambda m: "\\" + m.group(0), text.replace("\r\n", " ").replace("\n", " ")
                           .replace("\r", " "))
    if not line_start:
        return flat
    marker = lambda m: m.group(0) + "\\" if m.group(0)[0].isdigit() else "\\" + m.group(0)   # 1\. and \-
    return _MD_LINE_START.sub(marker, flat)


def _escape(fmt: str):
    """The escape of cell and header text for ``fmt`` (md's labels serve html and the DataFrame too, so
    Markdown escapes as it renders, and html as it renders)."""
    return _tex_escape if fmt == "tex" else str


def _render_md(head: list[str], body: list[list[str]], notes: list[str]) -> str:
    align = ["---" if i == 0 else "---:" for i in range(len(head))]
    lines = ["| " + " | ".join(map(_md_escape, r)) + " |" for r in [head, align, *body]]
    if notes:
        lines += [""] + [f"- {_md_escape(n, line_start=True)}" for n in notes]
    return "\n".join(lines) + "\n"


def _render_csv(head: list[str], body: list[list[str]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(head)
    writer.writerows(body)
    return buf.getvalue()


def _render_tex(head: list[str], body: list[list[str]], notes: list[str], caption: str) -> str:
    spec = "l" + "r" * (len(head) - 1)
    lines = [r"\begin{table}[htbp]", r"\centering", rf"\caption{{{_tex_escape(caption)}}}",
             rf"\begin{{tabular}}{{{spec}}}", r"\toprule", " & ".join(head) + r" \\", r"\midrule"]
    lines += [" & ".join(row) + r" \\" for row in body]
    lines += [r"\bottomrule", r"\end{tabular}"]
    if notes:
        lines += [r"\par\smallskip\footnotesize", r"\begin{itemize}"]
        lines += [rf"\item {_tex_escape(n)}" for n in notes] + [r"\end{itemize}"]
    lines.append(r"\end{table}")
    return "\n".join(lines) + "\n"


def html_table(head: list[str], body: list[list[str]], notes: list[str], caption: str) -> str:
    """An HTML ``<table>`` (plus a notes list); text escaped, numbers right-aligned by class."""
    e = html.escape
    parts = ['<table class="modal-table">', f"<caption>{e(caption)}</caption>", "<thead><tr>"]
    parts += [f"<th>{e(h)}</th>" for h in head] + ["</tr></thead>", "<tbody>"]
    for row in body:
        cells = "".join(f'<td class="{"num" if i else "key"}">{e(c)}</td>' for i, c in enumerate(row))
        parts.append(f"<tr>{cells}</tr>")
    parts.append("</tbody></table>")
    if notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{e(n)}</li>" for n in notes) + "</ul>")
    return "\n".join(parts)


_HTML_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse}}
th,td{{border-bottom:1px solid #ccc;padding:.25em .6em}} td.num{{text-align:right}}</style>
</head><body>
{table}
</body></html>
"""


def render(comp: Comparison, fmt: str = "md", layout: str = "modes",
           caption: str = "Measured and predicted natural frequencies") -> str:
    """The comparison as text in ``fmt`` (md | csv | tex | html | json); html is a complete page.

    csv and json carry full-precision numbers (json: a list of row objects keyed by the csv headers,
    ``null`` for empty cells, strict JSON); md, tex and html round for display."""
    if fmt not in FORMATS:
        raise CompareError(f"--format: unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
    if layout not in LAYOUTS:
        raise CompareError(f"--layout: unknown layout {layout!r} (expected one of {', '.join(LAYOUTS)})")
    cols, rows = _modes_grid(comp) if layout == "modes" else _sources_grid(comp)
    label_fmt = {"html": "md", "json": "csv"}.get(fmt, fmt)
    head = [_header(c, label_fmt) for c in cols]
    if fmt == "json":
        labels = _LABELS["csv"]
        return json.dumps([{h: labels[str(v)] if c.quantity == "quantity" else _plain(c.quantity, v)
                            for h, c, v in zip(head, cols, row, strict=True)} for row in rows],
                          indent=1, allow_nan=False) + "\n"
    body = _cells(cols, rows, label_fmt)
    notes = comp.notes()
    if fmt == "md":
        return _render_md(head, body, notes)
    if fmt == "csv":
        return _render_csv(head, body)
    if fmt == "tex":
        return _render_tex(head, body, notes, caption)
    return _HTML_PAGE.format(title=html.escape(caption), table=html_table(head, body, notes, caption))


def html_fragment(comp: Comparison, layout: str = "modes",
                  caption: str = "Measured and predicted natural frequencies") -> str:
    """The comparison as an HTML ``<table>`` fragment (used by the report)."""
    cols, rows = _modes_grid(comp) if layout == "modes" else _sources_grid(comp)
    return html_table([_header(c, "md") for c in cols], _cells(cols, rows, "md"), comp.notes(), caption)
