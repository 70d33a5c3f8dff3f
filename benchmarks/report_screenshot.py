"""Look at the reproduction report as a reader does: headless Chromium screenshots and a DOM probe.

    python benchmarks/report_screenshot.py [REPORT.html] [--out DIR] [--width 1280] [--height 900]

Default report: ``docs/results/report.html`` (the committed run). Writes ``DIR/first_screen.png`` (the page as it
opens), ``DIR/figure_section.png`` (the RSS baseline's section: its figure at the page width) and
``DIR/probe.json``: what the browser laid out — every in-page link and whether its target exists, the headings, the
computed text alignment of the claims' statements, each figure's displayed width and the smallest text size of
the page. Needs ``chromium`` (Debian: ``apt-get install chromium``); ``tests/test_report_screenshot.py`` uses the
same functions and skips, saying so, without it.
"""

from __future__ import annotations

import argparse
import html
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The section the second screenshot shows (its anchor in the report).
FIGURE_SECTION = "baseline-rss-against-the-papers-shield"

#: Run in the page after layout: writes what the browser computed into a <pre id="probe"> (read by --dump-dom).
_PROBE_JS = """
<script>
window.addEventListener('load', () => {
  const ids = new Set([...document.querySelectorAll('[id]')].map(e => e.id));
  const links = [...document.querySelectorAll('a[href^="#"]')].map(a => a.getAttribute('href').slice(1));
  const headings = [...document.querySelectorAll('h1,h2,h3,h4')].map(h => [h.tagName, h.textContent.trim()]);
  const cells = [...document.querySelectorAll('td')];
  const statements = cells.filter(td => td.textContent.startsWith('Ordering CV_all'))
    .map(td => getComputedStyle(td).textAlign);
  const numbers = cells.filter(td => /^[+-]?\\d+\\.\\d{3}$/.test(td.textContent.trim()))
    .map(td => getComputedStyle(td).textAlign);
  const figures = [...document.querySelectorAll('figure img')].map(img => ({
    alt: img.alt, shown: img.getBoundingClientRect().width, natural: img.naturalWidth}));
  const body = document.body.getBoundingClientRect();
  let small = 1e9;
  for (const el of document.querySelectorAll('p, li, td, th, figcaption, a, h2, h3')) {
    if (el.textContent.trim()) small = Math.min(small, parseFloat(getComputedStyle(el).fontSize));
  }
  const out = {ids: [...ids], links, headings, statements, numbers, figures, page_height: body.height,
               content_width: document.body.clientWidth, smallest_font_px: small};
  const pre = document.createElement('pre'); pre.id = 'probe'; pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""


def find_chromium() -> str | None:
    """The headless browser on PATH (``chromium``, ``chromium-browser``, ``google-chrome``), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        if path := shutil.which(name):
            return path
    return None


def _run(args: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
    chrome = find_chromium()
    if chrome is None:
        raise FileNotFoundError("chromium is not installed (Debian: apt-get install chromium)")
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--no-first-run",
             "--disable-dev-shm-usage", f"--user-data-dir={tempfile.mkdtemp(prefix='chromium-')}"]  # fmt: skip
    env = {**os.environ, "HOME": os.environ.get("HOME", "/tmp")}
    return subprocess.run([chrome, *flags, *args], capture_output=True, text=True, timeout=timeout, env=env)


def screenshot(page: Path, png: Path, *, width: int = 1280, height: int = 900, anchor: str | None = None) -> Path:
    """A screenshot of ``page`` in a ``width`` × ``height`` window; with ``anchor`` (an element id), of that section.

    For a section, the page is copied with a script that keeps only the section in the body, with the page's own
    style and width (headless ``--screenshot`` captures the top of the page: neither a URL fragment nor a scroll on
    load moves it)."""
    page, png = Path(page).resolve(), Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    source = page
    if anchor:
        text = page.read_text(encoding="utf-8")
        scroll = (f"<script>document.body.replaceChildren(document.getElementById({json.dumps(anchor)}));"
                  "</script>")  # fmt: skip
        source = png.with_suffix(".page.html")
        source.write_text(text.replace("</body>", scroll + "</body>"), encoding="utf-8")
    _run([f"--window-size={width},{height}", f"--screenshot={png}", "--virtual-time-budget=3000", source.as_uri()])
    if source != page:
        source.unlink()
    if not png.exists():
        raise RuntimeError(f"chromium wrote no screenshot of {page}")
    return png


def probe(page: Path, *, width: int = 1280, height: int = 900) -> dict:
    """What Chromium laid out for ``page`` (see the module docstring), from ``--dump-dom`` with a probe script."""
    page = Path(page).resolve()
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / page.name
        copy.write_text(page.read_text(encoding="utf-8").replace("</body>", _PROBE_JS + "</body>"), encoding="utf-8")
        done = _run([f"--window-size={width},{height}", "--virtual-time-budget=3000", "--dump-dom", copy.as_uri()])
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    if found is None:
        raise RuntimeError(f"the probe did not run: {done.stderr[-500:]}")
    return json.loads(html.unescape(found.group(1)))


def blank(png: Path) -> bool:
    """True when the screenshot is one colour (nothing rendered)."""
    from matplotlib.image import imread

    pixels = imread(png)[..., :3].reshape(-1, 3)
    return bool((pixels == pixels[0]).all())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("report", nargs="?", type=Path, default=ROOT / "docs" / "results" / "report.html")
    ap.add_argument("--out", type=Path, default=Path("results/screenshots"))
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=900)
    args = ap.parse_args(argv)
    if find_chromium() is None:
        print("chromium is not installed (Debian: apt-get install chromium)", file=sys.stderr)
        return 2
    first = screenshot(args.report, args.out / "first_screen.png", width=args.width, height=args.height)
    section = screenshot(args.report, args.out / "figure_section.png", width=args.width, height=args.height,
                         anchor=FIGURE_SECTION)  # fmt: skip
    info = probe(args.report, width=args.width, height=args.height)
    (args.out / "probe.json").write_text(json.dumps(info, indent=1), encoding="utf-8")
    dead = sorted(set(info["links"]) - set(info["ids"]))
    print(f"{first} (blank: {blank(first)})\n{section} (blank: {blank(section)})")
    print(f"page {info['page_height']:.0f} px tall, content {info['content_width']} px wide; {len(info['links'])} "
          f"in-page links, dead: {dead or 'none'}; smallest font {info['smallest_font_px']} px")  # fmt: skip
    for fig in info["figures"]:
        print(f"  figure {fig['alt']!r}: shown {fig['shown']:.0f} px of {fig['natural']} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
