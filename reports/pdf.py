"""The HTML report printed to PDF by headless Chromium (``flexmodal report --pdf``).

Chromium prints the report with its print style sheet (A4, whole tables with their header repeated on
each page) and every run's collapsed block opened (a copy of the page with ``<details open>``, in a
temporary folder; the report itself is not touched).  Chromium runs headless with a throw-away profile,
no network services, under ``timeout``; the PDF is written next to nothing else and moved into place
whole (checked_io.output.atomic_path).  Where no Chromium is installed the error is one line saying so.

The PDF is marked as flexmodal's by an incremental update (ISO 32000-1, 7.5.6) appended to Chromium's
file: a new document information dictionary whose ``/Creator`` is :data:`PDF_CREATOR`.  Only a PDF that
ends with that update is one ``report --pdf`` replaces beside its report (checked_io.output.sidecar_file);
any other PDF (a manuscript, one saved again by a viewer) is the user's.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from flexmodal.checked_io.output import atomic_path
from flexmodal.checked_io.text import read_text
from flexmodal.reports.errors import ReportError

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--no-pdf-header-footer")
PRINT_TIMEOUT_S = 120
PDF_SIGNATURE = b"%PDF-"   # how every PDF file starts (ISO 32000-1, 7.5.2)
PDF_CREATOR = b"/Creator (flexmodal report --pdf)"   # the mark of a PDF flexmodal wrote (see above)
_TRAILER = re.compile(rb"trailer\s*<<(?P<dict>.*?)>>\s*startxref\s+(?P<xref>\d+)\s+%%EOF\s*$", re.DOTALL)


def find_chromium() -> str | None:
    """Path of a Chromium (or Chrome) executable on PATH or at /usr/bin/chromium; None if none."""
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").is_file() else None


def marked_as_ours(pdf: bytes) -> bytes:
    """``pdf`` with an incremental update whose information dictionary is the old one with ``/Creator``
    replaced by :data:`PDF_CREATOR`; ``pdf`` unchanged when its end is not a classic cross-reference
    table and trailer with ``/Size``, ``/Root`` and ``/Info`` (then the next ``--pdf`` refuses to
    replace it, the safe side).

    Examples
    --------
    >>> old = b"%PDF-1.4\\n1 0 obj\\n<</Title (T) /Creator (C)>>\\nendobj\\nxref\\n0 2\\n" \\
    ...       b"trailer\\n<</Size 2 /Root 1 0 R /Info 1 0 R>>\\nstartxref\\n9\\n%%EOF\\n"
    >>> new = marked_as_ours(old)
    >>> new[len(old):].splitlines()[:2], new.endswith(b"%%EOF\\n")
    ([b'2 0 obj', b'<</Title (T)  /Creator (flexmodal report --pdf)>>'], True)
    >>> re.search(rb"trailer\\n(.*)\\nstartxref\\n(\\d+)", new[len(old):]).groups()
    (b'<</Size 3 /Root 1 0 R /Info 2 0 R /Prev 9>>', b'188')
    >>> new[188:192], new[123:130], b"0000000123 00000 n \\n" in new
    (b'xref', b'2 0 obj', True)
    """
    trailer = _TRAILER.search(pdf)
    if trailer is None:
        return pdf
    fields = trailer["dict"]
    size, root, info = (re.search(rb"/%s\s+(\d+(?:\s+\d+\s+R)?)" % key, fields)
                        for key in (b"Size", b"Root", b"Info"))
    if size is None or root is None or info is None:
        return pdf
    number = info[1].split()[0]
    old = re.search(rb"(?<!\d)%s\s+0\s+obj\s*<<(?P<body>.*?)>>\s*endobj" % number, pdf, re.DOTALL)
    if old is None:
        return pdf
    body = re.sub(rb"/Creator\s*\((?:\\.|[^\\()])*\)", b"", old["body"])
    new = int(size[1])
    start = len(pdf) if pdf.endswith(b"\n") else len(pdf) + 1
    obj = b"%d 0 obj\n<<%s %s>>\nendobj\n" % (new, body, PDF_CREATOR)
    xref = b"xref\n%d 1\n%010d 00000 n \ntrailer\n<</Size %d /Root %s /Info %d 0 R /Prev %s>>\n" % (
        new, start, new + 1, root[1], new, trailer["xref"])
    return (pdf if pdf.endswith(b"\n") else pdf + b"\n") + obj + xref + b"startxref\n%d\n%%%%EOF\n" % (
        start + len(obj))


def opened_for_print(html: str) -> str:
    """The page with every ``<details>`` block open (printing shows what a reader could expand).

    Examples
    --------
    >>> opened_for_print('<details class="run"><summary>a</summary></details>')
    '<details open class="run"><summary>a</summary></details>'
    """
    return re.sub(r"<details(?![^>]*\bopen\b)", "<details open", html)


def print_pdf(html_path: str | Path, pdf_path: str | Path, chromium: str | None = None,
              timeout_s: float = PRINT_TIMEOUT_S) -> Path:
    """Print the report ``html_path`` to ``pdf_path`` with headless Chromium; return ``pdf_path``.

    ReportError (one line) when no Chromium is found, when it fails or when it runs past ``timeout_s``.
    """
    exe = chromium or find_chromium()
    if exe is None:
        raise ReportError(f"report --pdf: no Chromium found (looked for {', '.join(CHROMIUM_NAMES)} on PATH "
                          f"and /usr/bin/chromium); the HTML report is {html_path}")
    html = read_text(Path(html_path), ReportError, "HTML report")
    if not html.lstrip("\ufeff \t\r\n")[:15].lower().startswith(("<!doctype html", "<html")):
        raise ReportError(f"{html_path}: not an HTML page (it does not start with <!DOCTYPE html> or "
                          "<html>); nothing printed")
    target = Path(pdf_path)
    with tempfile.TemporaryDirectory(prefix="flexmodal-pdf-") as tmp, atomic_path(target) as part:
        page = Path(tmp) / "report.html"
        page.write_text(opened_for_print(html), encoding="utf-8")
        printed = Path(tmp) / "report.pdf"
        cmd = ["timeout", "-k", "5", str(int(timeout_s)), exe, *CHROMIUM_FLAGS,
               f"--user-data-dir={Path(tmp) / 'profile'}", f"--print-to-pdf={printed}", page.as_uri()]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s + 10,
                                  stdin=subprocess.DEVNULL)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise ReportError(f"report --pdf: {exe} did not print {html_path}: {exc}") from None
        if done.returncode == 124:
            raise ReportError(f"report --pdf: {exe} did not finish printing {html_path} in {timeout_s:g} s")
        if done.returncode != 0 or not printed.is_file() or printed.stat().st_size == 0:
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise ReportError(f"report --pdf: {exe} failed (exit {done.returncode}): {last}")
        part.write_bytes(marked_as_ours(printed.read_bytes()))
    return target
