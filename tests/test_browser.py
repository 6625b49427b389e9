"""The HTML reports in a real browser: headless Chromium (Debian's ``chromium``).

Each page is copied beside itself with a probe script first in <head>: it records console
errors, uncaught exceptions and failed resource loads, and on ``load`` writes, into the DOM,
whether every <img> decoded (naturalWidth > 0). Chromium's ``--dump-dom`` returns the DOM, so
no driver or extra package is needed. A screenshot of each page is saved under
``generated_reports/browser/``.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
from report_fixtures import built

from pipeline.paths import PROJECT_ROOT

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
    out.textContent = JSON.stringify({images: imgs, errors: errors});
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


def screenshot(page: Path, name: str) -> Path:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    target = SCREENSHOTS / name
    target.unlink(missing_ok=True)
    chromium(page, f"--screenshot={target}", "--window-size=1280,2400", "--hide-scrollbars")
    return target


@pytest.mark.parametrize("page", ["index.html", "t_nominal/mechanism.html"])
def test_page_loads_every_figure_without_errors(page):
    path = built().reports / page
    result = probe(path)
    images = result["images"]
    assert images, f"{page}: no <img> on the page"
    broken = [i["src"] for i in images if not (i["complete"] and i["naturalWidth"] > 0)]
    assert not broken, f"{page}: figures that did not load: {broken}"
    assert not result["errors"], f"{page}: {result['errors']}"
    assert not result["stderr_errors"], f"{page}: {result['stderr_errors']}"
    shot = screenshot(path, page.replace("/", "_").replace(".html", ".png"))
    assert shot.is_file() and shot.stat().st_size > 10_000


def test_the_probe_catches_a_missing_figure(tmp_path):
    """The check can fail: a page with a broken <img> is reported."""
    page = tmp_path / "broken.html"
    page.write_text("<!DOCTYPE html><html><head><title>t</title></head><body>"
                    '<img src="figures/none.png" alt="missing"></body></html>')
    result = probe(page)
    assert result["images"][0]["naturalWidth"] == 0
    assert any("none.png" in e for e in result["errors"])
