"""The report page as a browser shows it: Debian's headless Chromium loads ``index.html`` and
dumps the DOM it built; the text a reader sees holds no raw Python (dict or array reprs, nan,
None as a value) and every figure has a caption.

Skipped when Chromium is not installed (``apt-get install -y chromium``)."""

from __future__ import annotations

import re
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

import nscontrol.report as report_mod
from nscontrol.examples import Example, ExampleResult, check, verdict_from
from nscontrol.examples._figures import new_figure, save_figure

BROWSER = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    BROWSER is None, reason="headless Chromium is not installed (Debian: apt-get install -y "
                            "chromium); the report's browser check needs it")

#: Raw Python text that must not reach a reader: reprs of dicts, arrays and numpy scalars, and
#: nan / None / inf shown as values (a whole table cell or list item).
RAW = (re.compile(r"\{'"), re.compile(r"array\("), re.compile(r"np\.(float|int|bool)"),
       re.compile(r"dtype="), re.compile(r"(^|[\s>:=(\[,])(nan|None|inf)($|[\s<,)\]])"))


def _awkward(out_dir):
    """An example with the metrics that used to come out raw (nan, None keys and values, inf,
    matrices, nested dicts, complex arrays) and a figure the example gives no caption."""
    figures = []
    for name in ("key", "uncaptioned"):
        fig, ax = new_figure()
        ax.plot([0, 1], [0, 1])
        ax.set(xlabel="t [s]", ylabel="q [m]")
        save_figure(fig, out_dir, name, figures)
    metrics = {None: float("nan"), "rate": float("inf"), "missing": None,
               "gains": [[1.0, 2.0], [3.0, 4.0]], "matrix": np.eye(3),
               "long": np.linspace(0, 1, 500), "mu": np.array([0.5 + 0.1j, 0.5 - 0.1j]),
               "nested": {"alpha": np.float64(0.123456789), "flags": [True, False],
                          "gap": float("nan")},
               "records": [{"a": 1.0}, {"a": None}], "n": np.int64(7)}
    checks = [check("residual_after_reaching", np.float64(3e-15), 1e-12)]
    return ExampleResult("awkward", metrics, checks, figures, summary="all fine")


AWKWARD = Example("awkward", "An awkward example", "ch99", _awkward,
                  claim="The first sentence of the claim.",
                  verdict=verdict_from(("residual", "residual")),
                  captions={"key": "Look at the key curve."}, key_figure="key")


class _Visible(HTMLParser):
    """The text a reader sees (outside script and style) and the figures with their
    captions."""

    def __init__(self) -> None:
        super().__init__()
        self.text: list[str] = []
        self.figures: list[dict[str, str]] = []
        self._skip = 0
        self._in: str | None = None

    def handle_starttag(self, tag, attrs):
        if tag in ("script", "style", "title"):
            self._skip += 1
        elif tag == "figure":
            self.figures.append({"img": "", "caption": ""})
        elif tag == "img" and self.figures:
            self.figures[-1]["img"] = dict(attrs).get("src") or ""
        elif tag == "figcaption":
            self._in = "figcaption"

    def handle_endtag(self, tag):
        if tag in ("script", "style", "title"):
            self._skip -= 1
        elif tag == "figcaption":
            self._in = None

    def handle_data(self, data):
        if self._skip:
            return
        self.text.append(data)
        if self._in == "figcaption" and self.figures:
            self.figures[-1]["caption"] += data


@needs_chromium
def test_the_report_page_in_headless_chromium_shows_no_raw_text(tmp_path, monkeypatch,
                                                                 tmp_path_factory):
    monkeypatch.setattr(report_mod, "all_examples", lambda: [AWKWARD])
    report_mod.write_report(tmp_path, progress=False)
    profile = tmp_path_factory.mktemp("chromium-profile")
    dom = subprocess.run([BROWSER, "--headless", "--no-sandbox", "--disable-gpu",
                          "--disable-background-networking", "--no-first-run",
                          f"--user-data-dir={profile}", "--dump-dom",
                          (tmp_path / "index.html").as_uri()],
                         capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0 and "<section" in dom.stdout, dom.stderr[-2000:]
    page = _Visible()
    page.feed(dom.stdout)
    # the metrics sit in a closed <details>: still in the DOM, shown when opened
    text = "\n".join(page.text)
    assert "Metrics" in text and "not computed" in text
    raw = [(p.pattern, m.group(0)) for p in RAW for m in p.finditer(text)]
    assert not raw, raw
    assert len(page.figures) == 2
    for fig in page.figures:
        assert fig["img"] and fig["caption"].strip(), fig     # every figure is captioned


def test_the_raw_text_patterns_catch_what_they_name():
    """The check can fail: each pattern finds its raw form and leaves plain words alone."""
    for raw in ("{'a': 1}", "array([1., 2.])", "np.float64(0.5)", "dtype=float64",
                "<td>nan</td>", "gap: None", "rate = inf"):
        assert any(p.search(raw) for p in RAW), raw
    for fine in ("not computed", "infinity: ∞", "Nonexistent", "nano", "(default)"):
        assert not any(p.search(fine) for p in RAW), fine
