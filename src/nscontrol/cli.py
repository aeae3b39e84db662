"""The ``nscontrol`` command: ``list``, ``run``, ``report``, ``bench``, ``warmup``,
``bifurcation``, ``sweep``."""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import click


@click.group()
@click.version_option(package_name="nscontrol")
def main() -> None:
    """Control and observer design for non-smooth systems."""
    # a command runs many and long simulations, timed: its kernels compile in the foreground
    # (a Python session's first run is interpreted while they compile in the background)
    os.environ.setdefault("NSCONTROL_COMPILE", "wait")


@main.command("list")
def list_examples() -> None:
    """List the runnable examples."""
    from .examples import all_examples

    examples = all_examples()
    width = max(len(ex.name) for ex in examples)
    for ex in examples:
        click.echo(f"{ex.name:{width}s}  {ex.chapter:10s} {ex.title}")


@main.command()
@click.argument("name")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for the example's figures (default: out/NAME).")
@click.option("--no-figures", is_flag=True, help="Write no figures (checks and metrics only).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object of metrics/checks.")
def run(name: str, out: Path | None, no_figures: bool, as_json: bool) -> None:
    """Run one example (NAME as `nscontrol list` prints it, or its chapter, e.g. ch08) and
    write its figures; exit status 0 only when every check passed."""
    from .errors import ModelError
    from .examples import get_example
    from .report import check_output_folder

    try:
        example = get_example(name)
        if no_figures and out is not None:
            raise click.UsageError("--out and --no-figures: give one of them")
        if not no_figures:
            out = out if out is not None else Path("out") / example.name
            check_output_folder(out, "--out")
    except KeyError as exc:
        raise click.UsageError(str(exc.args[0])) from None
    except ModelError as exc:
        raise click.UsageError(str(exc)) from None
    from ._progress import announce_compilation
    from .examples import format_value

    announce_compilation()
    start = time.perf_counter()
    result = example.run(out)
    seconds = time.perf_counter() - start
    if as_json:
        click.echo(json.dumps({**result.to_json(), "passed": result.passed,
                               "seconds": round(seconds, 3)}))
    else:
        for c in result.checks:
            mark = "pass" if c.passed else "FAIL"
            click.echo(f"[{mark}] {c.name}: {format_value(c.value)} {c.op} "
                       f"{format_value(c.threshold)}")
        for fig in result.figures:
            click.echo(f"figure: {fig}")
        click.echo(_run_summary(example, result, seconds))
    sys.exit(0 if result.passed else 1)


def _run_summary(example: Any, result: Any, seconds: float) -> str:
    """``NAME (12.3 s): Reproduced: <numbers>; n of n checks pass.`` on one line."""
    return f"{example.name} ({seconds:.1f} s): {example.verdict_line(result)}"


@main.command()
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, metavar="N",
              help="Groups of kernels compiled side by side, each in its own process "
                   "(default: one per core).")
def warmup(jobs: int | None) -> None:
    """Compile the numerical kernels now (once per install) so that later runs start fast."""
    from ._processes import default_jobs
    from ._progress import uncompiled_kernel_modules
    from .examples.warmup import STEPS, warm_up

    missing = uncompiled_kernel_modules()
    if not missing:
        click.echo("kernels already compiled (numba cache is up to date); nothing to do")
        return
    n_jobs = min(jobs if jobs is not None else default_jobs(), len(STEPS))
    click.echo(f"compiling {len(missing)} kernel modules in {len(STEPS)} groups, {n_jobs} at a "
               f"time (once per install; about 5 min of CPU in all); a line per group as it "
               f"ends...", err=True)
    start = time.perf_counter()
    try:
        failed = warm_up(lambda what: click.echo(f"  {what}", err=True), jobs=n_jobs)
    except KeyboardInterrupt:
        click.echo("warmup: interrupted; kernels not compiled yet compile on first use",
                   err=True)
        sys.exit(130)
    for line in failed:
        click.echo(f"  failed (its kernels compile on first use): {line}", err=True)
    left = uncompiled_kernel_modules()
    click.echo(f"warmup: compiled in {time.perf_counter() - start:.0f} s"
               + (f"; still compiled on first use: {', '.join(left)}" if left else ""))


@main.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out"),
              show_default=True, help="Folder for index.html, report.json and figures.")
@click.option("--only", multiple=True, help="Run only these examples (repeatable).")
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, metavar="N",
              help="Examples run side by side, each in its own process (default: one per "
                   "core; 1: one after another in this process).")
def report(out: Path, only: tuple[str, ...], jobs: int | None) -> None:
    """Run every example and write OUT/index.html with figures, metrics and checks."""
    from ._processes import default_jobs
    from .errors import ModelError
    from .report import check_output_folder, select_examples, write_report

    try:                        # both refused before anything runs or is overwritten
        select_examples(list(only) or None)
        check_output_folder(out, "--out")
    except ModelError as exc:
        raise click.UsageError(str(exc).replace("only:", "--only:", 1)) from None
    from ._progress import announce_compilation

    announce_compilation()
    n_jobs = jobs if jobs is not None else default_jobs()
    start = time.perf_counter()
    try:
        summary = write_report(out, list(only) or None, jobs=n_jobs)
    except KeyboardInterrupt:
        click.echo("report: interrupted; the examples' processes are stopped and no report "
                   "was written (a previous one is left as it was)", err=True)
        sys.exit(130)
    for ex in summary["examples"]:
        mark = "pass" if ex["passed"] else "FAIL"
        click.echo(f"[{mark}] {ex['example']} ({ex['seconds']:.1f} s)")
    n_ok = sum(ex["passed"] for ex in summary["examples"])
    total = sum(ex["seconds"] for ex in summary["examples"])
    click.echo(f"{n_ok}/{len(summary['examples'])} examples reproduced in "
               f"{time.perf_counter() - start:.0f} s ({total:.0f} s of examples, "
               f"{n_jobs} at a time); report: {out / 'index.html'}")
    sys.exit(0 if summary["passed"] else 1)


class _ListingFamilies(click.Command):
    """``bifurcation --help`` ends with the examples that define a parameter family and the
    names each can vary (found when the help is shown, so ``nscontrol`` starts fast)."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, ", ".join(params)) for name, params in bifurcation_families()]
        with formatter.section("Examples with a parameter family"):
            formatter.write_dl(rows or [("(none)", "")])
        formatter.write_paragraph()
        formatter.write_text("e.g. nscontrol bifurcation impact-oscillator-bifurcation "
                             "--param forcing=0.2:2.2:200")


def bifurcation_families() -> list[tuple[str, tuple[str, ...]]]:
    """``(example, parameter names)`` for every example whose module defines
    ``bifurcation_family`` (and ``bifurcation_parameters``, the names it takes)."""
    from .examples import all_examples

    out = []
    for ex in all_examples():
        module = sys.modules[ex.run.__module__]
        if getattr(module, "bifurcation_family", None) is not None:
            names = getattr(module, "bifurcation_parameters", lambda: ())()
            out.append((ex.name, tuple(names)))
    return out


@main.command(cls=_ListingFamilies)
@click.argument("example")
@click.option("--param", "param", required=True, metavar="NAME=START:STOP:N",
              help="Parameter of the example's family and its grid.")
@click.option("--scheduler", default=None, help="Dask scheduler address (default: serial).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out"),
              show_default=True, help="Folder for bifurcation.h5 and bifurcation.png.")
def bifurcation(example: str, param: str, scheduler: str | None, out: Path) -> None:
    """Brute-force bifurcation diagram of EXAMPLE's parameter family (up and down sweeps)."""
    from .analysis.bifurcation import bifurcation_diagram, parse_grid
    from .errors import ModelError
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
    try:                # an unknown parameter name: the family lists the valid ones
        factory = family(name)
    except ModelError as exc:
        raise click.UsageError(f"--param: {name!r} is no parameter of example {example!r} "
                               f"({exc})") from None
    try:                # every option is checked before the sweep runs
        bd = bifurcation_diagram(factory, values, executor=scheduler or "serial",
                                 progress=True, parameter_name=name)
    except ModelError as exc:
        text = str(exc)
        if text.startswith("executor:"):
            text = "--scheduler:" + text[len("executor:"):]
        raise click.UsageError(text) from None
    out.mkdir(parents=True, exist_ok=True)
    bd.save(out / "bifurcation.h5")
    import matplotlib
    matplotlib.use("Agg")
    ax = bd.plot()
    ax.figure.savefig(out / "bifurcation.png", dpi=110)
    click.echo(f"{len(bd.values)} values, {len(bd.errors)} failed; "
               f"wrote {out / 'bifurcation.h5'} and {out / 'bifurcation.png'}")


class _ListingSweeps(click.Command):
    """``sweep --help`` ends with the examples that offer sweeps and their parameters."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        from .examples import all_examples
        from .examples.sweeps import example_sweeps

        rows = [(f"{ex.name} {name}", spec.label) for ex in all_examples()
                for name, spec in example_sweeps(ex).items()]
        with formatter.section("Sweepable parameters (EXAMPLE NAME: what it is)"):
            formatter.write_dl(rows or [("(none)", "")])
        formatter.write_paragraph()
        formatter.write_text("e.g. nscontrol sweep ch07-friction-compensation "
                             "--param kappa=0.3:1.5:13")


@main.command(cls=_ListingSweeps)
@click.argument("example")
@click.option("--param", "param", required=True, metavar="NAME=START:STOP:N",
              help="The parameter and its grid.")
@click.option("--scheduler", default=None,
              help="Dask scheduler address (default: local processes when it pays).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out"),
              show_default=True, help="Folder for the sweep's JSON and figure.")
def sweep(example: str, param: str, scheduler: str | None, out: Path) -> None:
    """Sweep one parameter of EXAMPLE over a grid (local processes or a Dask cluster); a
    failed point is recorded and the others kept."""
    from .analysis.bifurcation import parse_grid
    from .errors import ModelError
    from .examples import get_example
    from .examples.sweeps import run_sweep
    from .report import check_output_folder

    try:
        name, values = parse_grid(param)
        ex = get_example(example)
        check_output_folder(out, "--out")
    except (KeyError, ValueError) as exc:
        raise click.UsageError(str(exc.args[0])) from None
    except ModelError as exc:
        raise click.UsageError(str(exc)) from None
    try:
        json_path, png_path, res = run_sweep(ex, name, list(values), out=out,
                                             executor=scheduler or "auto")
    except ModelError as exc:
        text = str(exc)
        for arg in ("param", "executor"):
            if text.startswith(f"{arg}:"):
                text = ("--scheduler" if arg == "executor" else "--param") + text[len(arg):]
        raise click.UsageError(text) from None
    click.echo(f"{len(res.grid)} points, {len(res.failed)} failed; wrote {json_path} and "
               f"{png_path}")
    sys.exit(0 if res.ok else 1)


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
    from ._progress import announce_compilation, progress_iter

    announce_compilation()      # on stderr: stdout stays one JSON object per line
    sys.path.insert(0, str(folder))
    for bname in [name] if name else available:
        spec = importlib.util.spec_from_file_location(f"bench_{bname}",
                                                      folder / f"bench_{bname}.py")
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        # one tick per scenario, on stderr (stdout stays one JSON object per line)
        for record in progress_iter(module.run(quick=quick), desc=f"bench {bname}"):
            record = plain_json(record)
            if as_json:
                click.echo(json.dumps(record))
            else:
                click.echo(_bench_line(record))


def plain_json(value: Any) -> Any:
    """``value`` with numpy scalars and arrays turned into Python numbers and lists (so no
    ``np.float64(...)`` text reaches a line), non-finite floats as strings."""
    from .examples import jsonable

    return jsonable(value)


def _bench_line(r: dict) -> str:
    """One readable line per scenario; ``ref`` names the reference measured in the same run
    (``ref[none]=—`` when there is none, followed by the reason: Siconos absent, or no
    reference implementation of this scenario)."""
    from .examples import format_value

    speed = r.get("ours_steps_per_s") or r.get("ours_s_per_solve")
    unit = "steps/s" if r.get("ours_steps_per_s") else "s/solve"
    ref = r.get("reference_steps_per_s") or r.get("reference_s_per_solve")
    ratio = r.get("ratio")
    ratio_s = f"{ratio:.3g}x" if isinstance(ratio, (int, float)) else "n/a"
    ref_name = r.get("reference") or "none"
    ref_s = "—" if ref is None else format_value(ref)
    why = (f" ({r.get('note') or 'no reference implementation for this scenario'})"
           if ref is None else "")
    acc = r.get("accuracy")
    acc_s = (", ".join(f"{k}={format_value(v)}" for k, v in acc.items())
             if isinstance(acc, dict) else format_value(acc))
    return (f"{r['scenario']:40s} size={format_value(r.get('size')):>6s} "
            f"ours={format_value(speed)} {unit} ref[{ref_name}]={ref_s}{why} ratio={ratio_s} "
            f"accuracy: {acc_s}")


if __name__ == "__main__":  # pragma: no cover
    main()
