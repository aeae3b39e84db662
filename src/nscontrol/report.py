"""``nscontrol report``: run every example and write ``index.html`` (figures, metrics, checks)."""

from __future__ import annotations

import html
import json
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

from ._files import replaced_atomically
from .errors import ModelError
from .examples import Example, ExampleResult, all_examples, format_value
from .examples import numeric_array as _as_numeric_array


def check_output_folder(out: Any, name: str = "out") -> Path:
    """``out`` as a folder that exists (created if needed) and accepts a new file; checked
    before any example runs, so a bad path fails in a second, not after the whole run.

    Raises
    ------
    ModelError
        ``out`` is a file, cannot be created (e.g. ``/dev/null/x``), or is not writable.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ModelError(f"{name}: {str(out)!r} is a file, not a folder; pass a folder path")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise ModelError(f"{name}: cannot write into folder {str(out)!r} ({exc.strerror or exc}); "
                         "pass a writable folder") from None
    return out


def select_examples(names: list[str] | None) -> list[Example]:
    """The examples called ``names`` (all when ``None``), in the catalogue's order.

    Raises
    ------
    ModelError
        A name that is no example (listing the known ones), or an empty selection.
    """
    examples = all_examples()
    if names is None:
        return examples
    known = [e.name for e in examples]
    unknown = [n for n in dict.fromkeys(names) if n not in known]
    if unknown:
        raise ModelError(f"only: unknown example name(s) {unknown}; known examples: "
                         f"{', '.join(known)} (see `nscontrol list`)")
    if not names:
        raise ModelError("only: expected at least one example name; omit --only to run all")
    return [e for e in examples if e.name in names]


def _write_atomically(path: Path, text: str) -> None:
    """``path`` replaced in one step: a failure leaves the previous file whole."""
    with replaced_atomically(path) as tmp:
        tmp.write_text(text)


def run_example(example: Example, out_dir: Path | None) -> tuple[ExampleResult | None, str, float]:
    """Run one example; returns (result or None, error text, seconds)."""
    start = time.perf_counter()
    try:
        result = example.run(out_dir)
        return result, "", time.perf_counter() - start
    except Exception:  # noqa: BLE001 - a failing example is reported, the others still run
        return None, traceback.format_exc(), time.perf_counter() - start


def write_report(out: Path, names: list[str] | None = None, *, progress: bool | None = None,
                 jobs: int | None = None) -> dict[str, Any]:
    """Run the examples (all, or ``names``) into ``out``; write ``index.html`` and
    ``report.json``. Returns the JSON summary.

    ``jobs`` examples run side by side, each in its own process (default: one per core;
    ``1`` runs them one after another in this process). The rows, their order and the
    pages are the same either way; a failing example is reported and the others kept.
    With several jobs, what an example prints goes to ``out/NAME/output.txt``.

    The names, ``jobs`` and the folder are checked before anything runs: an unknown name,
    a bad ``jobs`` or an unwritable folder raises :class:`~nscontrol.errors.ModelError` and
    leaves a previous report untouched. Both files are replaced atomically.
    """
    from ._processes import check_jobs

    examples = select_examples(names)
    n_jobs = check_jobs(jobs)
    out = check_output_folder(out)
    if n_jobs == 1 or len(examples) == 1:
        runs = _run_here(examples, out, progress)
    else:
        runs = _run_in_processes(examples, out, min(n_jobs, len(examples)), progress)
    rows: list[dict[str, Any]] = [
        {"example": ex, "result": result, "error": error, "seconds": seconds}
        for ex, (result, error, seconds) in zip(examples, runs, strict=True)]
    summary: dict[str, Any] = {
        "examples": [
            {**(r["result"].to_json() if r["result"] else {"example": r["example"].name}),
             "title": r["example"].title, "chapter": r["example"].chapter,
             "passed": bool(r["result"] and r["result"].passed), "error": r["error"],
             "seconds": round(r["seconds"], 3)}
            for r in rows],
    }
    summary["passed"] = all(e["passed"] for e in summary["examples"])
    _write_atomically(out / "report.json", json.dumps(summary, indent=2))
    _write_atomically(out / "index.html", _html(rows, out))
    return summary


_Run = tuple[ExampleResult | None, str, float]

#: What most examples import (their heavy imports are inside ``run``): imported once before
#: the examples' processes start, which then inherit them (:func:`nscontrol._processes.preload`)
#: instead of spending about 2 s of CPU each on importing them again.
SHARED_IMPORTS = ("numpy", "scipy.integrate", "scipy.linalg", "scipy.optimize", "numba",
                  "matplotlib.pyplot", "cvxpy", "nscontrol.simulate", "nscontrol.systems",
                  "nscontrol.design")


def _run_here(examples: list[Example], out: Path, progress: bool | None) -> list[_Run]:
    """The examples one after another in this process (``jobs=1``)."""
    from ._progress import progress_iter

    return [run_example(ex, out / ex.name)
            for ex in progress_iter(examples, total=len(examples), desc="examples",
                                    enable=progress, label=lambda e: e.name)]


def _run_in_processes(examples: list[Example], out: Path, jobs: int,
                      progress: bool | None) -> list[_Run]:
    """The examples ``jobs`` at a time, each in its own process (:mod:`nscontrol._processes`);
    the bar counts those finished and names the last one with its verdict, wall and CPU time."""
    from ._processes import Outcome, run_each
    from ._progress import ITER_DELAY, LineBar, count_bar
    from ._validation import check_bool

    shown = check_bool("progress", progress, allow_none=True) is not False
    bar = count_bar(len(examples), desc="examples", delay=ITER_DELAY) if shown else None

    def done(index: int, outcome: Outcome) -> None:
        result = outcome.value[0] if outcome.value is not None else None
        verdict = "failed to run" if result is None else "pass" if result.passed else "FAIL"
        text = (f"examples (finished {examples[index].name}: {verdict}, {outcome.seconds:.0f} s, "
                f"CPU {outcome.cpu:.0f} s)")
        if isinstance(bar, LineBar):        # a log: one line per finished example
            bar.n += 1
            bar.set_description_str(text, refresh=True)
        elif bar is not None:
            bar.set_description_str(text, refresh=False)
            bar.update(1)

    order = _longest_first(examples, out)
    try:
        done_in_order = run_each([(_run_named, (examples[i].name, out / examples[i].name))
                                  for i in order], jobs,
                                 on_done=lambda k, outcome: done(order[k], outcome),
                                 shared=SHARED_IMPORTS)
    finally:
        if bar is not None:
            bar.close()
    outcomes = [done_in_order[order.index(i)] for i in range(len(examples))]
    runs: list[_Run] = []
    for ex, o in zip(examples, outcomes, strict=True):
        if o.output.strip():
            folder = out / ex.name
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "output.txt").write_text(o.output)
        runs.append(o.value if o.value is not None else (None, o.error, o.seconds))
    return runs


def _longest_first(examples: list[Example], out: Path) -> list[int]:
    """The order to start the examples in: the longest first by the previous report's times
    in ``out`` (the pool then ends with short ones, not one long example on one core);
    examples without a previous time first, in the catalogue's order."""
    try:
        previous = {r["example"]: float(r["seconds"])
                    for r in json.loads((out / "report.json").read_text())["examples"]}
    except (OSError, ValueError, KeyError, TypeError):
        previous = {}
    return sorted(range(len(examples)),
                  key=lambda i: -previous.get(examples[i].name, float("inf")))


def _run_named(name: str, out_dir: Path) -> _Run:
    """:func:`run_example` of the example called ``name`` (in a child process)."""
    return run_example(select_examples([name])[0], out_dir)


_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:auto;padding:0 1em;
     line-height:1.45;color:#222}
table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ccc;padding:3px 8px;vertical-align:top;text-align:left}
th{background:#f3f3f3} td.num{text-align:right;font-variant-numeric:tabular-nums;
     white-space:nowrap}
td.pass,td.fail{font-weight:normal} td.pass b{color:#070} td.fail b{color:#b00}
.pass{color:#070;font-weight:600}.fail{color:#b00;font-weight:600}
.verdict{font-size:1.05em;padding:.4em .6em;border-left:4px solid #070;background:#f4faf4}
.verdict.fail{border-color:#b00;background:#fbf3f3}
.claim{font-size:1.05em} .chapter{color:#666;font-weight:normal;font-size:.8em}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #eee}
figcaption{color:#444;font-size:.92em;max-width:900px}
small{color:#555} details{margin:.5em 0} summary{cursor:pointer;color:#335}
table.sub td,table.sub th{border-color:#e3e3e3;padding:1px 5px;font-size:.92em}
"""

#: At most this many entries of a dict or list are drawn inline; larger ones fold away.
_INLINE_ENTRIES = 12


def _html(rows: list[dict[str, Any]], out: Path) -> str:
    """The report page: a summary of every chapter, then one section per chapter."""
    rows = _reading_order(rows)
    parts = ["<!doctype html><html lang='en'><meta charset='utf-8'>",
             "<meta name='viewport' content='width=device-width,initial-scale=1'>",
             f"<title>nscontrol — examples report</title><style>{_STYLE}</style>",
             "<h1>nscontrol — what each chapter claims, and whether this run reproduced it</h1>",
             _index_table(rows)]
    for r in rows:  # already in reading order
        parts.append(_section(r, out))
    return "\n".join(parts) + "\n</html>\n"


def _index_table(rows: list[dict[str, Any]]) -> str:
    """One row per chapter: title (linked), claim, verdict, runtime."""
    esc = html.escape
    n_ok = sum(bool(r["result"] and r["result"].passed) for r in rows)
    total = sum(r["seconds"] for r in rows)
    parts = [f"<p>{n_ok} of {len(rows)} examples reproduced their claims; "
             f"the run took {total:.0f} s.</p>",
             "<table><tr><th>chapter</th><th>example</th><th>claim</th><th>verdict</th>"
             "<th>runtime</th></tr>"]
    for r in rows:
        ex, res = r["example"], r["result"]
        ok = bool(res and res.passed)
        verdict = ex.verdict_line(res) if res is not None else "Failed to run (error below)."
        parts.append(
            f"<tr><td>{esc(ex.chapter)}</td><td><a href='#{esc(ex.name)}'>{esc(ex.title)}</a>"
            f"</td><td>{esc(_first_sentence(ex.claim))}</td>"
            f"<td class={'pass' if ok else 'fail'}>{_bold_head(verdict)}</td>"
            f"<td class=num>{r['seconds']:.1f} s</td></tr>")
    parts.append("</table>")
    return "\n".join(parts)


def _bold_head(verdict: str) -> str:
    """``"Reproduced: figures"`` with the word before the colon in bold."""
    head, _, rest = verdict.partition(": ")
    return f"<b>{html.escape(head)}</b>: {html.escape(rest)}" if rest else html.escape(verdict)


#: The order a reader meets the examples in: the building blocks, then the chapters.
_CHAPTER_ORDER = ("foundation", "mechanics", "set-valued")


def _reading_order(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    def key(r: dict[str, Any]) -> tuple[int, str, str]:
        chapter = r["example"].chapter
        rank = _CHAPTER_ORDER.index(chapter) if chapter in _CHAPTER_ORDER else 3
        return rank, chapter, r["example"].name
    return sorted(rows, key=key)


def _first_sentence(text: str) -> str:
    head, dot, _ = text.partition(". ")
    return head + (dot.strip() if dot else "")


def _section(r: dict[str, Any], out: Path) -> str:
    """A chapter: claim, verdict, key figure, checks, other figures, metrics."""
    esc = html.escape
    ex, res = r["example"], r["result"]
    parts = [f"<section id='{esc(ex.name)}'><h2>{esc(ex.title)} "
             f"<span class=chapter>{esc(ex.chapter)} · {esc(ex.name)} · "
             f"{r['seconds']:.1f} s</span></h2>"]
    if ex.claim:
        parts.append(f"<p class=claim>{esc(ex.claim)}</p>")
    if res is None:
        parts.append("<p class='verdict fail'>The example failed to run:</p>"
                     f"<pre>{esc(r['error'])}</pre></section>")
        return "\n".join(parts)
    parts.append(f"<p class='verdict{'' if res.passed else ' fail'}'>"
                 f"{esc(ex.verdict_line(res))}</p>")
    figures = ex.ordered_figures(res)
    parts += [_figure(ex, f, out) for f in figures[:1]]
    parts.append(_checks_table(res))
    parts += [_figure(ex, f, out) for f in figures[1:]]
    if res.summary:
        parts.append(f"<p><small>This run: {esc(res.summary)}</small></p>")
    if res.metrics:
        parts.append("<details><summary>Metrics (all figures measured; also in report.json)"
                     "</summary>" + _value_html(res.metrics) + "</details>")
    parts.append("</section>")
    return "\n".join(parts)


def _figure(ex: Example, path: Path, out: Path) -> str:
    esc = html.escape
    caption = ex.caption(path)
    src = Path(path).relative_to(out).as_posix()
    return (f"<figure><img src='{esc(src)}' alt='{esc(caption)}' loading='lazy'>"
            f"<figcaption>{esc(caption)}</figcaption></figure>")


_OP_TEXT = {"<=": "≤", "<": "<", ">=": "≥", ">": ">", "==": "="}


def _checks_table(res: ExampleResult) -> str:
    esc = html.escape
    parts = ["<table><tr><th>check</th><th>measured</th><th>bound</th><th>verdict</th></tr>"]
    for c in res.checks:
        note = f"<br><small>{esc(c.note)}</small>" if c.note else ""
        parts.append(
            f"<tr><td>{esc(plain_name(c.name))}{note}</td>"
            f"<td class=num>{esc(format_value(c.value))}</td>"
            f"<td class=num>{esc(_OP_TEXT.get(c.op, c.op))} {esc(format_value(c.threshold))}"
            f"</td><td class={'pass' if c.passed else 'fail'}>"
            f"{'pass' if c.passed else 'FAIL'}</td></tr>")
    parts.append("</table>")
    return "\n".join(parts)


def plain_name(name: str) -> str:
    """A check's identifier as words: ``"impact_count_exact_minus_dop853"`` → ``"Impact count
    exact minus dop853"``; names already in words keep their underscores (``alpha_max``)."""
    words = name.strip() if " " in name.strip() else name.replace("_", " ").strip()
    return words[:1].upper() + words[1:]


def _key_text(key: Any) -> str:
    """A metrics key as a row heading: numbers (e.g. the frequencies of a sweep) formatted,
    identifiers in words."""
    if key is None:     # a dict keyed by None: the entry of "no value of the parameter"
        return "(default)"
    try:
        return format_value(float(key))
    except (TypeError, ValueError):
        return plain_name(str(key))


def _value_html(value: Any, depth: int = 0) -> str:
    """Nested dicts as (foldable) sub-tables, small matrices as grids, scalars formatted."""
    esc = html.escape
    if isinstance(value, dict):
        rows = "".join(f"<tr><th>{esc(_key_text(k))}</th><td>{_value_html(v, depth + 1)}"
                       f"</td></tr>" for k, v in value.items())
        table = f"<table class=sub>{rows}</table>"
        if depth > 0 and len(value) > _INLINE_ENTRIES:
            return f"<details><summary>{len(value)} entries</summary>{table}</details>"
        return table
    arr = _as_numeric_array(value) if isinstance(value, (list, tuple)) or hasattr(
        value, "shape") else None
    if arr is not None and arr.ndim == 2 and arr.shape[0] <= 6 and arr.shape[1] <= 6:
        grid = "".join("<tr>" + "".join(f"<td class=num>{esc(format_value(v))}</td>"
                                        for v in row) + "</tr>" for row in arr)
        return (f"<table class=sub><caption>{arr.shape[0]} × {arr.shape[1]} matrix"
                f"</caption>{grid}</table>")
    if isinstance(value, (list, tuple)) and arr is None and len(value) <= _INLINE_ENTRIES \
            and all(isinstance(v, dict) for v in value):
        return "".join(_value_html(v, depth + 1) for v in value)
    return esc(format_value(value))
