"""Every user string of ``compare``'s text formats is shown as it is (adv27/REVIEW41): a configuration or
source name with ``<``, ``>`` or ``|`` came out of ``--format tex`` raw (¡ ¿ — in LaTeX's OT1 font), and
Markdown left ``<b>`` (an HTML tag), ``*x*`` and ``[a](u)`` (markup) and the notes' names raw.

The references are independent of the escapers: Markdown is rendered by markdown-it-py (CommonMark with
tables, a dependency through rich) and the text of each cell and note read back from its HTML; LaTeX is
read back by a reader of the text-mode rules written here (the ten special characters and ``<``, ``>``,
``|`` only as their commands, nothing else unescaped); HTML by html.parser; CSV by the csv module."""

from __future__ import annotations

import csv
import io
import re
from html.parser import HTMLParser

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st
from markdown_it import MarkdownIt

from flexmodal.compare.tables import compare_tables, render
from flexmodal.contract.table import ModalTable

# printable text without line breaks (a table reader keeps them out of names), a special character
# of each format among the first examples hypothesis tries
NAMES = st.text(st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Zl", "Zp")), min_size=1,
                max_size=30).map(str.strip).filter(bool) | st.sampled_from(
    ["<b>x</b>", "a|b", r"&%$#_{}~^\x", "[l](http://u)", "*x* `c`", "1. one", "- two", "# h", "&amp;"])

TEX_COMMANDS = {"textbackslash": "\\", "textasciitilde": "~", "textasciicircum": "^", "textless": "<",
                "textgreater": ">", "textbar": "|"}
TEX_MATH = {r"\zeta": "ζ", r"\Delta": "Δ", r"\Delta f": "Δf", "f": "f"}   # the labels' and escapes' math
TEX_TOKEN = re.compile(r"\\([a-z]+)\{\}|\\([&%$#_{}])|\$(\\zeta|\\Delta f|\\Delta|f)\$|(.)", re.S)


def _read_tex(text: str) -> str:
    """Text-mode LaTeX back to the characters it prints; AssertionError on an unescaped special."""
    out = []
    for command, escaped, math, char in TEX_TOKEN.findall(text):
        assert char == "" or char not in "\\&%$#_{}~^<>|", f"{char!r} unescaped in {text!r}"
        out.append(TEX_COMMANDS[command] if command else escaped or TEX_MATH.get(math) or char)
    return "".join(out)


class _Texts(HTMLParser):
    """The text of every ``td``, ``th`` and ``li`` of an HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.texts: list[str] = []
        self._open = False

    def handle_starttag(self, tag, attrs) -> None:
        assert tag in ("table", "thead", "tbody", "tr", "th", "td", "ul", "li", "caption", "p", "html",
                       "head", "meta", "title", "style", "body"), f"markup <{tag}> from a name"
        if tag in ("td", "th", "li"):
            self.texts.append("")
            self._open = True

    def handle_endtag(self, tag) -> None:
        self._open = self._open and tag not in ("td", "th", "li")

    def handle_data(self, data) -> None:
        if self._open:
            self.texts[-1] += data


def _texts(page: str) -> list[str]:
    parser = _Texts()
    parser.feed(page)
    return [t.strip() for t in parser.texts]


def _comparison(config: str, source: str):
    measured = pd.DataFrame({"config": [config, config], "mode": [1, 2], "freq_hz": [10.0, 40.0],
                             "damping_ratio": [0.01, 0.02]})
    predicted = pd.DataFrame({"config": [config], "mode": [1], "freq_hz": [10.5]})
    return compare_tables(ModalTable.from_frame(measured, "m.csv"),
                          [(source, ModalTable.from_frame(predicted, "p.csv"))])


@settings(max_examples=60, deadline=None)
@given(config=NAMES, source=NAMES)
def test_every_name_reads_back_as_it_is_in_every_text_format(config: str, source: str) -> None:
    comp = _comparison(config, source)
    note = f"{source}: no predicted mode pairs with measured mode 2 of {config} (40.00 Hz)"
    for layout in ("modes", "sources"):
        md = _texts(MarkdownIt("commonmark").enable("table").render(render(comp, "md", layout)))
        html = _texts(render(comp, "html", layout))
        for texts in (md, html):   # the source names a column or a row; the note names both
            assert f"{source} f [Hz]" in texts or source in texts
            assert note in texts
        tex = render(comp, "tex", layout)
        rows = [line.removesuffix(r" \\").split(" & ") for line in tex.splitlines() if line.endswith(r" \\")]
        cells = [_read_tex(c) for row in rows for c in row]
        assert f"{source} f [Hz]" in cells or source in cells
        assert note in [_read_tex(line.removeprefix("\\item ")) for line in tex.splitlines()
                        if line.startswith("\\item ")]
        table = list(csv.reader(io.StringIO(render(comp, "csv", layout))))
        assert f"{source}_freq_hz" in table[0] or source in [c for row in table for c in row]
