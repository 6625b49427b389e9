"""The HTML reports in a real browser: headless Chromium (Debian's ``chromium``).

The report is the shared short-run report (``report_fixtures.built``) copied and given a
two-point dt sweep, so that the index has every kind of artefact, the sweep table included.
Each page is copied beside itself with a probe script first in <head>: it records console
errors, uncaught exceptions and failed resource loads, and on ``load`` writes, into the DOM,
whether every <img> decoded (naturalWidth > 0). Chromium's ``--dump-dom`` returns the DOM, so
no driver or extra package is needed. A full-page screenshot of each page is saved under
``generated_reports/browser/`` (``index.png``, ``t_nominal_mechanism.png``) to be looked at.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from functools import cache
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
from report_fixtures import built

from pipeline.paths import PROJECT_ROOT
from pipeline.reports.render import render_all

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")]

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run",
         "--allow-file-access-from-files", "--virtual-time-budget=10000"]
SCREENSHOTS = PROJECT_ROOT / "generated_reports" / "browser"

PROBE = """<script>
(function () {
  var errors = [];
  var log = console.error;
  console.error = function () {
    errors.push("console.error: " + Array.prototype.join.call(arguments, " "));
    log.apply(console, arguments);
  };
  window.addEventListener("error", function (e) {
    var t = e.target;
    if (t && t !== window && (t.src || t.href)) {
      errors.push("failed to load " + (t.src || t.href));
    } else {
      errors.push("uncaught: " + e.message);
    }
  }, true);
  window.addEventListener("unhandledrejection", function (e) {
    errors.push("unhandled rejection: " + e.reason);
  });
  window.addEventListener("load", function () {
    var imgs = Array.prototype.map.call(document.images, function (i) {
      return {src: i.getAttribute("src"), complete: i.complete, naturalWidth: i.naturalWidth};
    });
    var out = document.createElement("pre");
    out.id = "probe-result";
    out.textContent = JSON.stringify({images: imgs, errors: errors,
                                      height: document.documentElement.scrollHeight});
    document.body.appendChild(out);
  });
})();
</script>"""


def chromium(page: Path, *extra: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile:
        return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *extra,
                               page.resolve().as_uri()],
                              capture_output=True, text=True, timeout=180)


def probe(page: Path) -> dict:
    """Load a probed copy of ``page`` (same folder, so relative links are unchanged)."""
    html = page.read_text()
    probed = page.with_name(f".probe-{page.name}")
    probed.write_text(re.sub(r"<head>", "<head>\n" + PROBE, html, count=1))
    try:
        r = chromium(probed, "--dump-dom")
    finally:
        probed.unlink()
    m = re.search(r'<pre id="probe-result">(.*?)</pre>', r.stdout, re.DOTALL)
    assert m, f"no probe result from chromium (exit {r.returncode}): {r.stderr[-2000:]}"
    text = m.group(1).replace("&quot;", '"').replace("&lt;", "<").replace("&gt;", ">")
    result = json.loads(text.replace("&amp;", "&"))
    # Chromium logs uncaught page errors on stderr as CONSOLE lines too.
    result["stderr_errors"] = [line for line in r.stderr.splitlines()
                               if "CONSOLE" in line and "Uncaught" in line]
    return result


def screenshot(page: Path, name: str, height: int) -> Path:
    """A screenshot of ``page`` in a window ``height`` pixels tall (the page's full length)."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    target = SCREENSHOTS / name
    target.unlink(missing_ok=True)
    chromium(page, f"--screenshot={target}", f"--window-size=1280,{height}",
             "--hide-scrollbars")
    return target


@cache
def report_with_sweep() -> Path:
    """The shared report, copied, with a real two-point dt sweep of t_nominal (each point run
    and analysed in this process, the table written as the sweep driver writes it), rendered."""
    from pipeline.sweep.driver import plan_sweep
    from pipeline.sweep.point import run_point
    from pipeline.sweep.results import make_table, write_table

    b = built()
    out = b.root / "reports_with_sweep"
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(b.reports, out)
    sweep = plan_sweep(b.spec_file("t_nominal"), ["mission.dt=0.01,0.03"], "t_dt",
                       b.root / "sweep_logs", out / "sweeps")
    records = [run_point(p.spec, str(sweep.log_dir)) for p in sweep.points]
    df = make_table(sweep.keys, [p.overrides for p in sweep.points], records)
    write_table(df, sweep.table_path, {"pipeline.sweep": sweep.name,
                                             "pipeline.keys": ",".join(sweep.keys)})
    render_all(out)
    return out


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if key in ("href", "src") and value:
                self.links.append(value)


def link_problems(page: Path, root: Path) -> list[str]:
    """Relative links of ``page`` that resolve to no file, and files under ``root`` that no
    link of ``page`` reaches (hidden files, the page itself and screenshots aside)."""
    parser = _Links()
    parser.feed(page.read_text())
    linked, wrong = set(), []
    for link in parser.links:
        parts = urlsplit(link)
        if parts.scheme or link.startswith("#"):
            continue
        target = (page.parent / unquote(parts.path)).resolve()
        if not target.is_file():
            wrong.append(f"dead link {link}")
        linked.add(target)
    for f in sorted(root.rglob("*")):
        rel = f.relative_to(root)
        if (f.is_file() and f.resolve() != page.resolve() and f.resolve() not in linked
                and not any(part.startswith(".") for part in rel.parts)
                and rel.parts[0] != "browser"):
            wrong.append(f"not linked: {rel.as_posix()}")
    return wrong


@pytest.mark.parametrize("page", ["index.html", "t_nominal/mechanism.html"])
def test_page_loads_every_figure_without_errors(page):
    path = report_with_sweep() / page
    result = probe(path)
    images = result["images"]
    assert images, f"{page}: no <img> on the page"
    broken = [i["src"] for i in images if not (i["complete"] and i["naturalWidth"] > 0)]
    assert not broken, f"{page}: figures that did not load: {broken}"
    assert not result["errors"], f"{page}: {result['errors']}"
    assert not result["stderr_errors"], f"{page}: {result['stderr_errors']}"
    shot = screenshot(path, page.replace("/", "_").replace(".html", ".png"),
                      result["height"] + 40)
    assert shot.is_file() and shot.stat().st_size > 10_000


def test_the_index_links_every_artefact_and_every_link_resolves():
    root = report_with_sweep()
    assert (root / "sweeps" / "t_dt" / "sweep.parquet").is_file()
    assert (root / "figures" / "sweep_t_dt.png").is_file()
    assert link_problems(root / "index.html", root) == []


def test_the_link_check_can_fail(tmp_path):
    (tmp_path / "sweeps" / "s").mkdir(parents=True)
    (tmp_path / "sweeps" / "s" / "sweep.parquet").write_bytes(b"x")
    (tmp_path / "a.json").write_text("{}")
    page = tmp_path / "index.html"
    page.write_text('<a href="a.json">a</a> <a href="gone.md">b</a> <img src="f.png">')
    assert link_problems(page, tmp_path) == ["dead link gone.md", "dead link f.png",
                                             "not linked: sweeps/s/sweep.parquet"]


def test_the_probe_catches_a_missing_figure(tmp_path):
    """The check can fail: a page with a broken <img> is reported."""
    page = tmp_path / "broken.html"
    page.write_text("<!DOCTYPE html><html><head><title>t</title></head><body>"
                    '<img src="figures/none.png" alt="missing"></body></html>')
    result = probe(page)
    assert result["images"][0]["naturalWidth"] == 0
    assert any("none.png" in e for e in result["errors"])
