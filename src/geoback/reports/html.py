"""report.html: report.md as one self-contained HTML file to hand on (to a client, a checker, an archive).

Every fact is written once, in report.md: this module renders that Markdown (markdown-it-py, CommonMark
with tables; raw HTML in the text is escaped, not passed through) and only adds what a document needs
around it: a header (case, date of the run, geoback version), the warnings at the top, a short "How to
read this report", a table of contents built from the Markdown's headings (so any section added to
report.md appears here without a change of this code) and a footer. Every image report.md links is
embedded as a data URI (a PNG as base64); links to other files are kept as their text, so the page
refers to nothing outside itself: no stylesheet, script or font is loaded, it reads offline, and the
print style sheet breaks pages before main sections, keeps table rows and figures whole and scales
figures to the page.
"""
from __future__ import annotations

import base64
import html
import re
from datetime import datetime
from pathlib import Path

from markdown_it import MarkdownIt

from geoback import __version__
from geoback.outputs import write_atomic

MIME = {".png": "image/png", ".svg": "image/svg+xml", ".jpg": "image/jpeg", ".jpeg": "image/jpeg",
        ".gif": "image/gif", ".webp": "image/webp"}

HOW_TO_READ = (
    "This report gives the result of a back-analysis: parameters of the ground (and, where asked, of the "
    "construction) were identified by maximum likelihood so that a plane-strain finite-element model reproduces "
    "the instruments' readings, each reading weighted by its stated accuracy. Read the warnings first: they say what "
    "not to trust. <em>The model</em> says what was fitted: the geometry, every value of the ground layers and "
    "structures (identified values in bold, with their 95 % interval; the others fixed at the case's values), "
    "the construction stages, the mesh and the instruments. <em>The fit</em> gives the estimates with their standard "
    "deviation and 95 % interval, how well the model explains the readings (the χ² test: a p-value below 0.05 says "
    "the readings differ from the model by more than their stated accuracy) and the correlations between estimates. "
    "Forecasts, where given, carry 95 % bands from the estimates' covariance. Moduli are in MPa (GPa for concrete "
    "and steel), displacements in mm, unit weights in kN/m³. Every number is also in the CSV files and summary.json "
    "beside this report, at full precision.")

CSS = """
:root { --ink: #1d2329; --muted: #5b6670; --rule: #c9d1d9; --band: #f3f6f9; --accent: #1f5f8b;
        --warn-bg: #fff4e5; --warn-rule: #e8a33d; --ok-bg: #eef7ee; --ok-rule: #5a9e5a; }
* { box-sizing: border-box; }
html { font-size: 15px; }
body { margin: 0; color: var(--ink); background: #fff; line-height: 1.45;
       font-family: "Segoe UI", "Helvetica Neue", Helvetica, Arial, "Liberation Sans", "DejaVu Sans", sans-serif; }
.page { max-width: 1120px; margin: 0 auto; padding: 24px 32px 48px; }
header.cover { border-bottom: 3px solid var(--accent); padding-bottom: 12px; margin-bottom: 18px; }
header .kicker { text-transform: uppercase; letter-spacing: .08em; color: var(--accent); font-size: .8rem;
                 margin: 0 0 4px; font-weight: 600; }
h1 { font-size: 1.9rem; margin: 0 0 8px; }
h2 { font-size: 1.35rem; color: var(--accent); border-bottom: 1px solid var(--rule); padding-bottom: 3px;
     margin: 32px 0 10px; }
h3 { font-size: 1.08rem; margin: 20px 0 6px; }
table.meta { border: none; margin: 0; font-size: .92rem; }
table.meta th, table.meta td, table.meta tr:nth-child(even) td { border: none; padding: 1px 14px 1px 0; background: none;
                                                          text-align: left; }
table.meta th { color: var(--muted); font-weight: 500; }
.notice { border-left: 5px solid var(--warn-rule); background: var(--warn-bg); padding: 8px 16px; margin: 14px 0; }
.notice.ok { border-left-color: var(--ok-rule); background: var(--ok-bg); }
.notice p:first-child { margin-top: 4px; }
.howto { font-size: .93rem; color: #2f3a44; }
nav.toc { background: var(--band); border: 1px solid var(--rule); padding: 6px 18px 10px; margin: 16px 0 8px; }
nav.toc h2 { border: none; margin: 8px 0 4px; font-size: 1.1rem; }
nav.toc ol { margin: 0; padding-left: 22px; } nav.toc ol ol { list-style: lower-alpha; }
nav.toc a { color: var(--ink); text-decoration: none; } nav.toc a:hover { text-decoration: underline; }
.table { overflow-x: auto; margin: 8px 0 12px; }
table { border-collapse: collapse; font-size: .88rem; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid var(--rule); padding: 3px 8px; vertical-align: top; }
th { background: var(--band); text-align: left; font-weight: 600; }
tbody tr:nth-child(even) td { background: #fafbfc; }
code { font-family: "DejaVu Sans Mono", Consolas, "Liberation Mono", monospace; font-size: .9em;
       background: var(--band); padding: 0 3px; border-radius: 3px; }
p.figure { text-align: center; margin: 6px 0 22px; }
p.figure img { max-width: 100%; height: auto; border: 1px solid var(--rule); }
.missing { color: #a33; font-style: italic; }
footer { margin-top: 40px; border-top: 1px solid var(--rule); padding-top: 8px; color: var(--muted);
         font-size: .82rem; }
@media print {
  @page { size: A4; margin: 15mm 13mm 16mm; }
  html { font-size: 10.5pt; }
  .page { max-width: none; padding: 0; }
  main h2 { break-before: page; page-break-before: always; }
  h2, h3, h4 { break-after: avoid; page-break-after: avoid; }
  p:has(+ p.figure) { break-after: avoid; page-break-after: avoid; }
  .table { overflow: visible; }
  table { break-inside: auto; }
  tr, td, th { break-inside: avoid; page-break-inside: avoid; }
  thead { display: table-header-group; }
  p.figure { break-inside: avoid; page-break-inside: avoid; }
  p.figure img { max-width: 100%; max-height: 23cm; border: none; }
  nav.toc { break-inside: avoid; }
  a { color: inherit; text-decoration: none; }
}
"""


def _slug(text: str, used: set) -> str:
    base = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"
    slug, k = base, 2
    while slug in used:
        slug, k = f"{base}-{k}", k + 1
    used.add(slug)
    return slug


def _data_uri(path: Path) -> str | None:
    mime = MIME.get(path.suffix.lower())
    if mime is None or not path.is_file():
        return None
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


def _local(target: str) -> bool:
    """A link to a file beside the report (not a page anchor, not a URL of any scheme)."""
    return not (target.startswith("#") or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", target) or target.startswith("//"))


def _self_contained(tokens, folder: Path) -> None:
    """Embed every image the Markdown links from `folder`; drop the links to anything else (their text
    stays): the page then refers to nothing outside itself. An image that is missing becomes a note."""
    for k, tok in enumerate(tokens):
        if tok.type != "inline" or not tok.children:
            continue
        children, kept = [], []  # kept: for each open link, whether it stays (a page anchor)
        for child in tok.children:
            if child.type == "image":
                src = child.attrGet("src") or ""
                uri = _data_uri(folder / src) if src and _local(src) else None
                if uri is None:
                    child.type, child.tag, child.nesting = "text", "", 0
                    child.content, child.attrs, child.children = f"[figure not found: {src}]", {}, None
                else:
                    child.attrSet("src", uri)
            elif child.type == "link_open":
                kept.append(str(child.attrGet("href") or "").startswith("#"))
                if not kept[-1]:
                    continue
            elif child.type == "link_close":
                if not (kept.pop() if kept else False):
                    continue
            children.append(child)
        tok.children = children
        if len(children) == 1 and children[0].type == "image" and k and tokens[k - 1].type == "paragraph_open":
            tokens[k - 1].attrSet("class", "figure")


def _headings(tokens) -> tuple[str, list[tuple[int, str, str]]]:
    """Give every h2-h4 an id; return the first h1's text and the (level, text, id) of each h2 and h3."""
    used: set = set()
    title, toc = "", []
    for k, tok in enumerate(tokens):
        if tok.type != "heading_open":
            continue
        text = tokens[k + 1].content if k + 1 < len(tokens) else ""
        level = int(tok.tag[1])
        if level == 1 and not title:
            title = text
            continue
        slug = _slug(text, used)
        tok.attrSet("id", slug)
        if level in (2, 3):
            toc.append((level, text, slug))
    return title, toc


def _without_title(tokens):
    """The tokens less the first h1 (the header shows it)."""
    for k, tok in enumerate(tokens):
        if tok.type == "heading_open" and tok.tag == "h1":
            return tokens[:k] + tokens[k + 3:]
    return tokens


def _toc_html(toc) -> str:
    if not toc:
        return ""
    out, depth = ["<nav class=\"toc\" aria-label=\"Contents\"><h2>Contents</h2><ol>"], 2
    first = True
    for level, text, slug in toc:
        if level > depth:
            out.append("<ol>")
        elif level < depth:
            out.append("</li></ol></li>")
        elif not first:
            out.append("</li>")
        depth, first = level, False
        out.append(f"<li><a href=\"#{slug}\">{html.escape(text)}</a>")
    out.append("</li>" + ("</ol></li>" if depth == 3 else "") + "</ol></nav>")
    return "".join(out)


DIAGNOSIS_HOW_TO_READ = (
    "This report gives a diagnosis of a back-analysis: where the fitted model fails to explain the instruments' "
    "readings, which additions to the model (hypotheses) were tried in rounds, how much better each fits (χ², "
    "AIC) and which was accepted, with every parameter before and after. Read the verdict at the top first. "
    "Moduli are in MPa, displacements in mm. Every number is also in diagnosis.json beside this report; "
    "amended.yaml, where written, is the case amended to go on with.")


def html_report(markdown: str, folder: Path, name: str, when: str, version: str = __version__,
                warnings: int | None = 0, kind: str = "back-analysis report", how_to_read: str = HOW_TO_READ) -> str:
    """The HTML page of a report's Markdown (module docstring); images are read from `folder`.
    `warnings`: how many the result carries (the text before the first section, where report.md
    writes them, is boxed as such; 0 says there are none); None: the report counts none, its opening
    text is shown as it is."""
    md = MarkdownIt("commonmark", {"html": False, "typographer": False}).enable("table")
    tokens = md.parse(markdown)
    title, toc = _headings(tokens)
    _self_contained(tokens, Path(folder))
    tokens = _without_title(tokens)
    first = next((k for k, t in enumerate(tokens) if t.type == "heading_open" and t.tag == "h2"), len(tokens))
    preamble = md.renderer.render(tokens[:first], md.options, {}).strip()
    body = md.renderer.render(tokens[first:], md.options, {})
    body = body.replace("<table>", "<div class=\"table\"><table>").replace("</table>", "</table></div>")
    preamble = preamble.replace("<table>", "<div class=\"table\"><table>").replace("</table>", "</table></div>")
    if warnings is None:
        notice = f"<div class=\"opening\">{preamble}</div>" if preamble else ""
    elif warnings:
        notice = f"<div class=\"notice\" role=\"alert\">{preamble}</div>"
    else:
        notice = ("<div class=\"notice ok\"><p><strong>No warnings</strong>: the result carries no caveat.</p>"
                  + preamble + "</div>")
    esc = html.escape
    meta = "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in
                   (("case", name), ("run", when), ("written by", f"geoback {version}")))
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="geoback {esc(version)}">
<title>{esc(title or name)}</title>
<style>{CSS}</style>
</head>
<body>
<div class="page">
<header class="cover">
<p class="kicker">geoback · {esc(kind)}</p>
<h1>{esc(title or name)}</h1>
<table class="meta">{meta}</table>
</header>
{notice}
<section class="howto"><h2 id="how-to-read-this-report">How to read this report</h2><p>{how_to_read}</p></section>
{_toc_html(toc)}
<main>
{body}</main>
<footer>Case {esc(name)} · run {esc(when)} · geoback {esc(version)}. One self-contained file: every figure is
embedded and nothing is loaded from elsewhere. The same content as report.md beside it.</footer>
</div>
</body>
</html>
"""


def run_date() -> str:
    """The date and time of the run, local, with its offset from UTC."""
    return datetime.now().astimezone().strftime("%Y-%m-%d %H:%M (UTC%z)")


def write_html(path: Path, markdown: str, folder: Path, res=None, name: str | None = None,
               kind: str = "back-analysis report", how_to_read: str = HOW_TO_READ) -> None:
    """Write report.html (atomically, into the run's result set) from the report's Markdown, with the
    images it links from `folder` embedded; `res` (an Identification) gives the case's name and the
    number of warnings (without it, none are counted)."""
    name = name or (res.name if res is not None else Path(folder).name)
    warnings = len(getattr(res, "caveats", ()) or ()) if res is not None else None
    write_atomic(path, html_report(markdown, folder, name, run_date(), warnings=warnings, kind=kind,
                                   how_to_read=how_to_read))
