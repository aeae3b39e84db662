"""``nscontrol report``: run every example and write ``index.html`` (figures, metrics, checks)."""

from __future__ import annotations

import html
import json
import os
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

from .errors import ModelError
from .examples import Example, ExampleResult, all_examples


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
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def run_example(example: Example, out_dir: Path | None) -> tuple[ExampleResult | None, str, float]:
    """Run one example; returns (result or None, error text, seconds)."""
    start = time.perf_counter()
    try:
        result = example.run(out_dir)
        return result, "", time.perf_counter() - start
    except Exception:  # noqa: BLE001 - a failing example is reported, the others still run
        return None, traceback.format_exc(), time.perf_counter() - start


def write_report(out: Path, names: list[str] | None = None, *, progress: bool | None = None
                 ) -> dict[str, Any]:
    """Run the examples (all, or ``names``) into ``out``; write ``index.html`` and
    ``report.json``. Returns the JSON summary.

    The names and the folder are checked before anything runs: an unknown name or an
    unwritable folder raises :class:`~nscontrol.errors.ModelError` and leaves a previous
    report untouched. Both files are replaced atomically.
    """
    from ._progress import progress_iter

    examples = select_examples(names)
    out = check_output_folder(out)
    rows: list[dict[str, Any]] = []
    for ex in progress_iter(examples, total=len(examples), desc="examples", enable=progress):
        result, error, seconds = run_example(ex, out / ex.name)
        rows.append({"example": ex, "result": result, "error": error, "seconds": seconds})
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


def _html(rows: list[dict[str, Any]], out: Path) -> str:
    esc = html.escape
    parts = ["<!doctype html><meta charset='utf-8'><title>nscontrol report</title>",
             "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
             "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px}"
             ".pass{color:#070}.fail{color:#b00}img{max-width:100%}</style>",
             "<h1>nscontrol — examples report</h1><ul>"]
    for r in rows:
        ok = r["result"] is not None and r["result"].passed
        parts.append(f"<li><a href='#{esc(r['example'].name)}'>{esc(r['example'].name)}</a> "
                     f"<span class={'pass' if ok else 'fail'}>{'pass' if ok else 'FAIL'}"
                     f"</span> ({r['seconds']:.1f} s)</li>")
    parts.append("</ul>")
    for r in rows:
        ex, res = r["example"], r["result"]
        parts.append(f"<h2 id='{esc(ex.name)}'>{esc(ex.name)} — {esc(ex.title)}</h2>"
                     f"<p>{esc(ex.chapter)}</p>")
        if res is None:
            parts.append(f"<pre class=fail>{esc(r['error'])}</pre>")
            continue
        if res.summary:
            parts.append(f"<p>{esc(res.summary)}</p>")
        parts.append("<table><tr><th>check</th><th>value</th><th></th><th>threshold</th>"
                     "<th>result</th></tr>")
        for c in res.checks:
            cls = "pass" if c.passed else "fail"
            name = esc(c.name) + (f"<br><small>{esc(c.note)}</small>" if c.note else "")
            parts.append(f"<tr><td>{name}</td><td>{esc(_fmt(c.value))}</td>"
                         f"<td>{esc(c.op)}</td><td>{esc(_fmt(c.threshold))}</td>"
                         f"<td class={cls}>{'pass' if c.passed else 'FAIL'}</td></tr>")
        parts.append("</table><h3>metrics</h3><table>")
        for k, v in res.metrics.items():
            parts.append(f"<tr><td>{esc(k)}</td><td>{esc(_fmt(v))}</td></tr>")
        parts.append("</table>")
        for fig in res.figures:
            parts.append(f"<p><img src='{esc(str(Path(fig).relative_to(out)))}'></p>")
    return "\n".join(parts)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)) and len(value) > 12:
        return f"[{len(value)} values] " + ", ".join(_fmt(v) for v in value[:6]) + ", …"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)
