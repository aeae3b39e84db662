"""The ``nscontrol`` command: ``list``, ``run``, ``report``, ``bench``, ``bifurcation``."""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import click


@click.group()
@click.version_option(package_name="nscontrol")
def main() -> None:
    """Control and observer design for non-smooth systems."""


@main.command("list")
def list_examples() -> None:
    """List the runnable examples."""
    from .examples import all_examples

    for ex in all_examples():
        click.echo(f"{ex.name:28s} {ex.chapter:10s} {ex.title}")


@main.command()
@click.argument("name")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for the example's figures (default: none written).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object of metrics/checks.")
def run(name: str, out: Path | None, as_json: bool) -> None:
    """Run one example; exit status 0 only when every check passed."""
    from .errors import ModelError
    from .examples import get_example
    from .report import check_output_folder

    try:
        example = get_example(name)
        if out is not None:
            check_output_folder(out, "--out")
    except KeyError as exc:
        raise click.UsageError(str(exc.args[0])) from None
    except ModelError as exc:
        raise click.UsageError(str(exc)) from None
    result = example.run(out)
    if as_json:
        click.echo(json.dumps(result.to_json()))
    else:
        for c in result.checks:
            mark = "pass" if c.passed else "FAIL"
            click.echo(f"[{mark}] {c.name}: {c.value} {c.op} {c.threshold}")
        for fig in result.figures:
            click.echo(f"figure: {fig}")
    sys.exit(0 if result.passed else 1)


@main.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out"),
              show_default=True, help="Folder for index.html, report.json and figures.")
@click.option("--only", multiple=True, help="Run only these examples (repeatable).")
def report(out: Path, only: tuple[str, ...]) -> None:
    """Run every example and write OUT/index.html with figures, metrics and checks."""
    from .errors import ModelError
    from .report import check_output_folder, select_examples, write_report

    try:                        # both refused before anything runs or is overwritten
        select_examples(list(only) or None)
        check_output_folder(out, "--out")
    except ModelError as exc:
        raise click.UsageError(str(exc).replace("only:", "--only:", 1)) from None
    summary = write_report(out, list(only) or None)
    for ex in summary["examples"]:
        mark = "pass" if ex["passed"] else "FAIL"
        click.echo(f"[{mark}] {ex['example']} ({ex['seconds']:.1f} s)")
    click.echo(f"report: {out / 'index.html'}")
    sys.exit(0 if summary["passed"] else 1)


@main.command()
@click.argument("example")
@click.option("--param", "param", required=True, metavar="NAME=START:STOP:N",
              help="Parameter of the example's family and its grid.")
@click.option("--scheduler", default=None, help="Dask scheduler address (default: serial).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out"),
              show_default=True, help="Folder for bifurcation.h5 and bifurcation.png.")
def bifurcation(example: str, param: str, scheduler: str | None, out: Path) -> None:
    """Brute-force bifurcation diagram of EXAMPLE's parameter family (up and down sweeps)."""
    from .analysis.bifurcation import bifurcation_diagram, parse_grid
    from .examples import get_example

    try:
        name, values = parse_grid(param)
        module = sys.modules[get_example(example).run.__module__]
    except (KeyError, ValueError) as exc:
        raise click.UsageError(str(exc.args[0])) from None
    family = getattr(module, "bifurcation_family", None)
    if family is None:
        raise click.UsageError(f"example {example!r} defines no parameter family "
                               f"(bifurcation_family)")
    bd = bifurcation_diagram(family(name), values, executor=scheduler or "serial",
                             progress=True, parameter_name=name)
    out.mkdir(parents=True, exist_ok=True)
    bd.save(out / "bifurcation.h5")
    import matplotlib
    matplotlib.use("Agg")
    ax = bd.plot()
    ax.figure.savefig(out / "bifurcation.png", dpi=110)
    click.echo(f"{len(bd.values)} values, {len(bd.errors)} failed; "
               f"wrote {out / 'bifurcation.h5'} and {out / 'bifurcation.png'}")


def bench_dir() -> Path:
    """The ``bench/`` folder of the source checkout (or ``$NSCONTROL_BENCH_DIR``)."""
    env = os.environ.get("NSCONTROL_BENCH_DIR")
    path = Path(env) if env else Path(__file__).resolve().parents[2] / "bench"
    if not path.is_dir():
        raise click.UsageError(f"benchmarks live in the source checkout's bench/ folder, not "
                               f"found at {path}; set NSCONTROL_BENCH_DIR")
    return path


@main.command()
@click.argument("name", required=False)
@click.option("--json", "as_json", is_flag=True, help="One JSON object per line and scenario.")
@click.option("--quick", is_flag=True, help="Smaller sizes and budgets (for smoke tests).")
def bench(name: str | None, as_json: bool, quick: bool) -> None:
    """Run benchmarks (all, or the one called NAME) against their references."""
    folder = bench_dir()
    available = sorted(p.stem[len("bench_"):] for p in folder.glob("bench_*.py"))
    if name is not None and name not in available:
        raise click.UsageError(f"no benchmark {name!r}; available: {', '.join(available)}")
    from ._progress import progress_iter

    sys.path.insert(0, str(folder))
    for bname in [name] if name else available:
        spec = importlib.util.spec_from_file_location(f"bench_{bname}",
                                                      folder / f"bench_{bname}.py")
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        # one tick per scenario, on stderr (stdout stays one JSON object per line)
        for record in progress_iter(module.run(quick=quick), desc=f"bench {bname}"):
            if as_json:
                click.echo(json.dumps(record))
            else:
                click.echo(_bench_line(record))


def _bench_line(r: dict) -> str:
    speed = r.get("ours_steps_per_s") or r.get("ours_s_per_solve")
    ref = r.get("reference_steps_per_s") or r.get("reference_s_per_solve")
    ratio = r.get("ratio")
    ratio_s = f"{ratio:.3g}x" if isinstance(ratio, (int, float)) else "n/a"
    return (f"{r['scenario']:40s} size={r.get('size')!s:>6s} ours={speed:.4g} "
            f"ref[{r.get('reference')}]={ref if ref is None else f'{ref:.4g}'} ratio={ratio_s} "
            f"accuracy={r.get('accuracy')}")


if __name__ == "__main__":  # pragma: no cover
    main()
