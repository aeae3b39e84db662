"""`nscontrol report` runs every example, keeps going past a failing one, and writes HTML+JSON."""

import json

from click.testing import CliRunner

import nscontrol.report as report_mod
from nscontrol.cli import main
from nscontrol.examples import Example, ExampleResult, check
from nscontrol.examples._figures import new_figure, save_figure


def _good(out_dir):
    figures = []
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    save_figure(fig, out_dir, "line", figures)
    return ExampleResult("good", {"err": 1e-13}, [check("err", 1e-13, 1e-10)], figures)


def _broken(out_dir):
    raise RuntimeError("deliberately broken example")


def test_report_writes_html_and_json_and_survives_failures(tmp_path, monkeypatch):
    fake = [Example("good", "a good one", "test", _good),
            Example("broken", "a broken one", "test", _broken)]
    monkeypatch.setattr(report_mod, "all_examples", lambda: fake)
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path)])
    assert result.exit_code == 1  # one example failed
    summary = json.loads((tmp_path / "report.json").read_text())
    by_name = {e["example"]: e for e in summary["examples"]}
    assert by_name["good"]["passed"] and not by_name["broken"]["passed"]
    assert "deliberately broken" in by_name["broken"]["error"]
    html = (tmp_path / "index.html").read_text()
    assert "good/line.png" in html and "deliberately broken" in html
    assert (tmp_path / "good" / "line.png").stat().st_size > 1000


# -- the page a reader sees ----------------------------------------------------------------
import re  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
from html.parser import HTMLParser  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from nscontrol.examples import format_value, verdict_from  # noqa: E402
from nscontrol.examples._figures import unlabelled_axes  # noqa: E402


def _rich(out_dir):
    """Metrics of every awkward shape the examples produce: nested dicts (one of 60 entries),
    matrices, long arrays, complex numbers, numpy scalars."""
    figures = []
    for name in ("key", "other"):
        fig, ax = new_figure()
        ax.plot([0, 1], [0, 1])
        ax.set(xlabel="t [s]", ylabel="q [m]")
        save_figure(fig, out_dir, name, figures)
    metrics = {"matrix": np.eye(3), "long": np.linspace(0, 1, 500),
               "nested": {"5.2": {"alpha": np.float64(0.123456789), "flags": [True, False]}},
               "big": {f"k{i}": float(i) for i in range(60)},
               "mu": np.array([0.5 + 0.1j, 0.5 - 0.1j]), "n": np.int64(7),
               "records": [{"a": 1.0}, {"a": 2.0}]}
    checks = [check("residual_after_reaching", np.float64(3e-15), 1e-12),
              check("observable", np.bool_(True), True, "==", note="plain words only")]
    return ExampleResult("rich", metrics, checks, figures, summary="all fine")


RICH = Example("rich", "A rich example", "ch99", _rich,
               claim="The first sentence of the claim. A second sentence.",
               verdict=verdict_from(("residual", "residual")),
               captions={"key": "Look at the key curve.", "other": "Look at the other one."},
               key_figure="key")


class _Images(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.ids, self.links = [], set(), []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.images.append(a)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "a" and a.get("href", "").startswith("#"):
            self.links.append(a["href"][1:])


@pytest.fixture
def rich_report(tmp_path, monkeypatch):
    monkeypatch.setattr(report_mod, "all_examples", lambda: [RICH])
    summary = report_mod.write_report(tmp_path, progress=False)
    return tmp_path, (tmp_path / "index.html").read_text(), summary


def test_html_has_no_raw_python_text_and_no_broken_images(rich_report):
    out, html, _ = rich_report
    assert "array(" not in html and "{'" not in html and "np.float64" not in html
    assert "spec §" not in html
    parser = _Images()
    parser.feed(html)
    assert len(parser.images) == 2
    for img in parser.images:
        assert (out / img["src"]).is_file(), img["src"]
        assert img.get("alt"), f"{img['src']} has no alt text"
    assert set(parser.links) <= parser.ids       # every index link lands on a section


def test_section_opens_with_claim_verdict_and_key_figure(rich_report):
    _, html, _ = rich_report
    section = html[html.index("<section id='rich'>"):]
    claim, verdict = section.index("A second sentence."), section.index("Reproduced: residual")
    key, table = section.index("rich/key.png"), section.index("<th>measured</th>")
    other = section.index("rich/other.png")
    assert claim < verdict < key < table < other
    assert "<figcaption>Look at the key curve.</figcaption>" in section
    assert "Residual after reaching" in section      # plain-language check name
    assert "plain words only" in section


def test_metrics_are_formatted_tables(rich_report):
    _, html, summary = rich_report
    assert "500 values from 0 to 1" in html                  # a long array is summarised
    assert "0.1235" in html and "0.123456789" not in html      # 4 significant digits
    assert "60 entries" in html                                # a big dict folds away
    assert re.search(r"<th>Alpha</th><td>0.1235</td>", html)   # nested dict: a sub-table
    assert summary["examples"][0]["metrics"]["nested"]["5.2"]["alpha"] == 0.123456789


@pytest.mark.parametrize("value, text", [
    (np.float64(1.23456789e-13), "1.23e-13"), (np.float64(2.5), "2.5"), (True, "yes"),
    (None, "—"), (np.int64(12345), "12 345"), ([1.0, 2.0], "[1, 2]"), ("text", "text")])
def test_format_value(value, text):
    assert format_value(value) == text


def test_unlabelled_axes_names_the_bare_panel():
    fig, axes = new_figure(2, 1, sharex=True)
    axes[0].plot([0, 1], [0, 1])
    axes[0].set_ylabel("q [m]")
    axes[1].plot([0, 1], [0, 1])
    axes[1].set_xlabel("t [s]")
    assert unlabelled_axes(fig) == ["panel 1 (untitled): no y label"]


def test_run_prints_a_timed_summary_and_json_carries_passed(monkeypatch, tmp_path):
    import nscontrol.examples as ex_mod

    monkeypatch.setattr(ex_mod, "all_examples", lambda: [RICH])
    runner = CliRunner()
    monkeypatch.chdir(tmp_path)
    as_json = runner.invoke(main, ["run", "rich", "--json", "--no-figures"])
    assert not (tmp_path / "out").exists()
    text = runner.invoke(main, ["run", "rich"])
    assert list((tmp_path / "out" / "rich").glob("*.png"))   # figures by default, in out/NAME
    assert text.exit_code == 0, text.output
    last = text.output.strip().splitlines()[-1]
    assert re.match(r"rich \(\d+\.\d s\): Reproduced: residual .*; 2 of 2 checks pass\.$", last)
    record = json.loads(as_json.stdout)   # a first-run compile notice goes to stderr
    assert record["passed"] is True and record["seconds"] >= 0


def test_bench_lines_and_json_have_no_numpy_reprs():
    from nscontrol.cli import _bench_line, plain_json

    record = plain_json({"scenario": "s", "size": np.int64(10),
                         "ours_steps_per_s": np.float64(1234.5), "reference": None,
                         "reference_steps_per_s": None, "ratio": None,
                         "accuracy": {"err": np.float64(1e-13)}})
    text = json.dumps(record) + _bench_line(record)
    assert "np." not in text and "float64" not in text
    assert "ref[none]=— (no reference implementation for this scenario)" in text


def test_compilation_is_announced_once(monkeypatch, capsys):
    import nscontrol._progress as progress

    monkeypatch.setattr(progress, "_announced", False)
    monkeypatch.setattr(progress, "uncompiled_kernel_modules", lambda: ["numerics._lcp_kernels"])
    assert progress.announce_compilation() and not progress.announce_compilation()
    err = capsys.readouterr().err
    assert err.count("compiling numerical kernels") == 1 and "once" in err


@pytest.mark.slow
def test_report_page_loads_in_headless_chromium_with_every_image_decoded(rich_report,
                                                                          tmp_path_factory):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("Debian's chromium is not installed (apt-get install -y chromium)")
    out, _, _ = rich_report
    # the page reports in its title how many images decoded (naturalWidth > 0) at `load`;
    # lazy images are made eager first, since an image below the fold would never load
    probe = out / "probe.html"
    probe.write_text((out / "index.html").read_text().replace(
        "</html>", "<script>const im = [...document.images]; im.forEach(i => i.loading = "
        "'eager'); window.addEventListener('load', () => {const ok = im.filter(i => i.complete "
        "&& i.naturalWidth > 0); document.title = 'decoded ' + ok.length + ' of ' + im.length;"
        "});</script></html>"))
    profile = tmp_path_factory.mktemp("chromium-profile")
    dom = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu",
                          f"--user-data-dir={profile}", "--virtual-time-budget=10000",
                          "--allow-file-access-from-files", "--dump-dom", probe.as_uri()],
                         capture_output=True, text=True, timeout=120)
    title = re.search(r"<title>(.*?)</title>", dom.stdout)
    assert title and title.group(1) == "decoded 2 of 2", (title, dom.stderr[-2000:])


def test_metrics_appendix_has_no_raw_python_text():
    from nscontrol.report import _value_html

    text = _value_html({None: float("nan"), "gains": [[1.0, 2.0], [3.0, 4.0]],
                        "rate": float("inf"), "zero": 0.0})
    for raw in (">nan<", ">None<", ">inf<", "0.0<"):
        assert raw not in text
    assert "not computed" in text and "(default)" in text and "2 × 2 matrix" in text
    assert "∞" in text
