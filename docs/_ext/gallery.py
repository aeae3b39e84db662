"""Write ``gallery.md`` at build time: every example, its chapter page and, when a report was
run, its figures.

Running the examples inside the docs build would take minutes, so the figures come from the
output of ``nscontrol report --out DIR`` when one exists (``NSCONTROL_REPORT_DIR``, else
``out/`` at the repository root); without it the page lists the examples and the commands
that draw their figures.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

# A chapter whose page is not named after it; the others use ``<chapter>.md`` when it exists.
CHAPTER_PAGES = {"set-valued": "setvalued", "foundation": "lcp",
                 "contacts": "frictional_contacts"}
FIGURE_DIR = "_gallery"          # under the docs source folder, ignored by git


def _report_dir(srcdir: Path) -> Path | None:
    candidate = Path(os.environ.get("NSCONTROL_REPORT_DIR", srcdir.parent / "out"))
    return candidate if (candidate / "report.json").is_file() else None


def _report_rows(report: Path | None) -> dict[str, dict[str, Any]]:
    if report is None:
        return {}
    data = json.loads((report / "report.json").read_text())
    return {row["example"]: row for row in data.get("examples", [])}


def _copy_figures(report: Path, name: str, dest: Path) -> list[Path]:
    figures = sorted((report / name).glob("*.png")) if (report / name).is_dir() else []
    (dest / name).mkdir(parents=True, exist_ok=True)
    for fig in figures:
        shutil.copy2(fig, dest / name / fig.name)
    return [Path(FIGURE_DIR) / name / fig.name for fig in figures]


def _chapter_page(chapter: str, srcdir: Path) -> str | None:
    page = CHAPTER_PAGES.get(chapter, chapter.replace("-", "_"))
    return page if (srcdir / f"{page}.md").is_file() else None


def _section(example: Any, row: dict[str, Any] | None, figures: list[Path],
             srcdir: Path) -> list[str]:
    lines = [f"## {example.name}", "", example.title + ".", ""]
    page = _chapter_page(example.chapter, srcdir)
    if page:
        lines += [f"Chapter page: [{page}]({page}.md).", ""]
    lines += ["```bash", f"nscontrol run {example.name} --out out/{example.name}", "```", ""]
    if row is not None:
        checks = row.get("checks", [])
        passed = sum(bool(c.get("passed")) for c in checks)
        verdict = "reproduced" if row.get("passed") else "NOT reproduced"
        lines += [f"Last report: {verdict}: {passed} of {len(checks)} checks pass "
                  f"({row.get('seconds', 0):.0f} s).", ""]
    for fig in figures:
        caption = fig.stem.replace("_", " ")
        lines += [f"```{{figure}} {fig.as_posix()}", f":alt: {caption}", ":width: 90%", "",
                  caption, "```", ""]
    return lines


def write_gallery(app: Any) -> None:
    """Sphinx ``builder-inited`` hook: (re)write ``gallery.md`` in the source folder."""
    from nscontrol.examples import all_examples

    srcdir = Path(app.srcdir)
    report = _report_dir(srcdir)
    rows = _report_rows(report)
    dest = srcdir / FIGURE_DIR
    shutil.rmtree(dest, ignore_errors=True)
    lines = ["# Gallery of the examples", ""]
    if report is None:
        lines += ["No report was found when these pages were built, so the figures are not "
                  "shown. `make demo` (or `nscontrol report --out out`) runs every example "
                  "and writes them; `make docs` then includes them here.", ""]
    else:
        lines += ["Figures of the last `nscontrol report` run, with its verdict for each "
                  "example.", ""]
    for example in all_examples():
        figures = _copy_figures(report, example.name, dest) if report else []
        lines += _section(example, rows.get(example.name), figures, srcdir)
    (srcdir / "gallery.md").write_text("\n".join(lines))


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", write_gallery)
    return {"parallel_read_safe": True, "version": "1"}
