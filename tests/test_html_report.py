"""report.html, the self-contained report beside report.md (reports/html.py).

- quick, no browser: the builder embeds every image report.md links, refers to nothing outside the
  file, keeps every section of the Markdown (a section it has never seen included), and escapes raw HTML;
- in a real headless Chromium: `geoback run cases/tunnel-paper.yaml --plots` writes a report.html that
  renders (title, the model section, the parameter table), whose images all load, with no console
  error and no request leaving the file. Without Chromium the test skips loudly, and fails when
  GEOBACK_REQUIRE_BROWSER=1 (as .ci/run sets it).
"""
from __future__ import annotations

import base64
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "tunnel-paper.yaml"
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync"]
# a 1x1 PNG
PIXEL = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5ErkJggg==")


def outside_references(text: str) -> list[str]:
    """Every src/href (and CSS url()) of the page that is neither a data URI nor an anchor in the page,
    and every http, https or file URL written anywhere in it."""
    refs = re.findall(r"""(?:src|href|srcset|action|poster|data)\s*=\s*["']?([^"'\s>]*)""", text, re.I)
    refs += re.findall(r"url\(\s*['\"]?([^'\")]*)", text, re.I)
    refs += re.findall(r"@import", text)
    bad = [r for r in refs if not (r.startswith("data:") or r.startswith("#"))]
    return bad + re.findall(r"(?:https?|file|ftp)://[^\s\"'<>]*", text, re.I)


def sections(markdown: str) -> list[str]:
    return [line.lstrip("#").strip() for line in markdown.splitlines() if re.match(r"#{2,3} ", line)]


# ------------------------------------------------------------------------------------------ the builder
@pytest.mark.quick
def test_builder_embeds_images_refers_to_nothing_outside_and_keeps_every_section(tmp_path):
    from geoback.reports.html import html_report

    (tmp_path / "a.png").write_bytes(PIXEL)
    (tmp_path / "b.png").write_bytes(PIXEL)
    markdown = "\n".join([
        "# geoback fit report: demo", "", "**Warnings**", "", "- [w1] something not to trust", "",
        "## The model", "", "### Ground", "", "| layer | E |", "|---|---|", "| clay | **10 MPa** |", "",
        "## The fit", "", "Raw <script>alert(1)</script> text, a [table](parameters.csv) and a "
        "[web page](https://example.org/x) and a [jump](#the-model).", "",
        "## Settlement trough", "", "A section this module has never heard of.", "",
        "## Figures", "", "![Figure 1: a](a.png)", "", "![Figure 2: b](b.png)", "", "![gone](missing.png)", ""])
    page = html_report(markdown, tmp_path, "demo", "2025-01-01 12:00", warnings=1)

    assert outside_references(page) == []
    assert page.count('src="data:image/png;base64,') == 2
    assert "[figure not found: missing.png]" in page
    assert "<script>" not in page and "&lt;script&gt;" in page  # raw HTML in the text is shown, not run
    assert "https://example.org" not in page and "web page" in page and 'href="#the-model"' in page
    for title in sections(markdown):  # every section, with an anchor the contents link to
        slug = re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")
        assert f'id="{slug}"' in page and f'href="#{slug}"' in page, title
    assert page.index("something not to trust") < page.index("How to read this report") < page.index('id="the-model"')
    assert 'role="alert"' in page and "<title>geoback fit report: demo</title>" in page
    assert "<table>" in page and "<strong>10 MPa</strong>" in page


@pytest.mark.quick
def test_a_report_without_warnings_says_so(tmp_path):
    from geoback.reports.html import html_report

    page = html_report("# t\n\n## A\n\ntext\n", tmp_path, "demo", "now")
    assert "No warnings" in page and outside_references(page) == []


# ------------------------------------------------------------------------------------------ in a browser
def chromium() -> str | None:
    for path in (os.environ.get("GEOBACK_CHROMIUM"), "/usr/bin/chromium", "/usr/bin/chromium-browser",
                 shutil.which("chromium"), shutil.which("chromium-browser"), shutil.which("google-chrome")):
        if path and Path(path).is_file() and os.access(path, os.X_OK):
            return path
    return None


def browser_or_skip():
    """Chromium and playwright, or a loud skip (a failure when GEOBACK_REQUIRE_BROWSER=1)."""
    why = None
    exe = chromium()
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        why = "the playwright package is not installed (pip install -e '.[test]')"
    if exe is None:
        why = "no Chromium found (apt-get install -y chromium; or set GEOBACK_CHROMIUM)"
    if why is None:
        return exe
    message = f"report.html NOT TESTED IN A BROWSER: {why}"
    if os.environ.get("GEOBACK_REQUIRE_BROWSER") == "1":
        pytest.fail(message + " (GEOBACK_REQUIRE_BROWSER=1)")
    pytest.skip(message)


def test_report_html_renders_in_headless_chromium(tmp_path):
    exe = browser_or_skip()
    from playwright.sync_api import sync_playwright

    out = tmp_path / "out"
    geoback = Path(sys.executable).with_name("geoback")
    command = [str(geoback)] if geoback.is_file() else [sys.executable, "-m", "geoback.commands.cli"]
    subprocess.run(command + ["run", str(CASE), "--plots", "--quiet", "--out", str(out)], check=True,
                   cwd=tmp_path, timeout=600)
    page_file = out / "report.html"
    text = page_file.read_text(encoding="utf-8")
    assert outside_references(text) == []
    markdown = (out / "report.md").read_text(encoding="utf-8")
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs and all(f"]({name})" in markdown for name in pngs)  # report.md links every figure written
    toc = re.search(r'<nav class="toc".*?</nav>', text, re.S).group(0)
    assert all(f">{title}</a>" in toc for title in sections(markdown))  # every section in the contents

    t0 = time.perf_counter()
    errors, requests, failed = [], [], []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=BROWSER_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("request", lambda r: requests.append(r.url))
            page.on("requestfailed", lambda r: failed.append(r.url))
            page.goto(page_file.as_uri(), wait_until="load")
            assert page.title() == "geoback fit report: tunnel-paper"
            assert "geoback fit report: tunnel-paper" in page.inner_text("h1")
            assert page.is_visible("#the-model") and page.is_visible("#the-fit")
            assert page.locator("nav.toc a[href='#the-model']").count() == 1
            headers = page.locator("table th").all_inner_texts()
            assert "estimate" in headers and "95 % interval" in headers  # the parameter table
            assert "E[clay]" in page.inner_text("main")
            images = page.evaluate("() => Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.alt])")
            assert len(images) == len(pngs)
            assert all(done and width > 0 for done, width, _ in images), images
            page.screenshot(path=str(tmp_path / "report.png"), full_page=False)
            page.pdf(path=str(tmp_path / "report.pdf"))  # printable: the print style sheet lays it out
        finally:
            browser.close()
    seconds = time.perf_counter() - t0
    assert errors == [], errors
    assert failed == [], failed
    assert [u for u in requests if not (u.startswith("data:") or u == page_file.as_uri())] == []
    assert (tmp_path / "report.png").stat().st_size > 10_000
    if os.environ.get("GEOBACK_SCREENSHOT"):  # keep the screenshot to look at it
        shutil.copy(tmp_path / "report.png", os.environ["GEOBACK_SCREENSHOT"])
        shutil.copy(tmp_path / "report.pdf", Path(os.environ["GEOBACK_SCREENSHOT"]).with_suffix(".pdf"))
    print(f"browser check: {seconds:.1f} s")
