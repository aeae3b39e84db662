"""The exception family, boundary validation, and the command-line shell."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from nscontrol import _validation as v
from nscontrol import errors
from nscontrol.cli import main


@pytest.mark.parametrize("cls, builtin", [
    (errors.ModelError, ValueError), (errors.DimensionError, ValueError),
    (errors.InadmissibleStateError, ValueError), (errors.InfeasibleDesignError, RuntimeError),
    (errors.SolverError, RuntimeError), (errors.ZenoError, RuntimeError),
])
def test_every_error_is_also_the_obvious_builtin(cls, builtin):
    assert issubclass(cls, errors.NscontrolError) and issubclass(cls, builtin)


def test_errors_carry_partial_trajectory():
    err = errors.ZenoError("accumulation at t=1", time=1.0, trajectory="partial")
    assert err.trajectory == "partial" and err.time == 1.0


def test_validation_messages_name_the_argument():
    with pytest.raises(errors.DimensionError, match=r"M: expected a square matrix, got shape"):
        v.as_square("M", np.zeros((2, 3)))
    with pytest.raises(errors.ModelError, match=r"q: expected finite entries, got 1 NaN"):
        v.as_vector("q", [1.0, np.nan])
    with pytest.raises(errors.ModelError, match="mass_matrix: expected a symmetric"):
        v.check_symmetric("mass_matrix", np.array([[1.0, 2.0], [0.0, 1.0]]))
    with pytest.raises(errors.ModelError, match="positive definite"):
        v.check_positive_definite("M", np.diag([1.0, -1.0]))
    with pytest.raises(errors.ModelError, match=r"e: expected a value in \[0.0, 1.0\]"):
        v.check_in_interval("e", 1.5, 0.0, 1.0)
    with pytest.raises(errors.ModelError, match="t_span"):
        v.check_t_span((1.0, 0.0))
    with pytest.raises(errors.DimensionError, match="reshape vectors explicitly"):
        v.as_matrix("B", [1.0, 2.0])


def test_simulate_rejects_unknown_method():
    import nscontrol as nsc

    with pytest.raises(errors.ModelError, match="method: expected one of"):
        nsc.simulate(object(), [0.0], (0.0, 1.0), method="rk4")
    with pytest.raises(errors.ModelError, match="no default_method"):
        nsc.simulate(object(), [0.0], (0.0, 1.0))


def test_cli_list_and_unknown_names():
    runner = CliRunner()
    result = runner.invoke(main, ["list"])
    assert result.exit_code == 0
    result = runner.invoke(main, ["run", "no-such-example"])
    assert result.exit_code != 0 and "no example 'no-such-example'" in result.output
    result = runner.invoke(main, ["bench", "no-such-bench"])
    assert result.exit_code != 0 and "no benchmark 'no-such-bench'" in result.output


def test_every_listed_example_has_a_unique_name_and_a_runner():
    from nscontrol.examples import all_examples

    names = [e.name for e in all_examples()]
    assert len(names) == len(set(names))
    assert all(callable(e.run) for e in all_examples())


def test_check_json_shape():
    from nscontrol.examples import ExampleResult, check

    res = ExampleResult("demo", metrics={"a": np.float64(1.5), "b": np.arange(3)},
                        checks=[check("small", 1e-12, 1e-10), check("big", 2.0, 3.0, ">=")])
    data = json.loads(json.dumps(res.to_json()))
    assert data["metrics"] == {"a": 1.5, "b": [0, 1, 2]}
    assert [c["passed"] for c in data["checks"]] == [True, False]
    assert not res.passed


def test_import_is_light():
    import subprocess
    import sys

    code = ("import sys, nscontrol; heavy = [m for m in ('numba', 'cvxpy', 'matplotlib', 'dask',"
            " 'h5py', 'scipy') if m in sys.modules]; print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_simulate_verb_survives_submodule_imports():
    import nscontrol
    import nscontrol.simulate.trajectory  # noqa: F401  (would rebind a lazily bound name)

    assert callable(nscontrol.simulate) and nscontrol.Trajectory.__name__ == "Trajectory"


@pytest.mark.parametrize("value", [[1.0 + 2.0j], np.array([1.0j]), np.complex128(1.0),
                                   [[1.0, 0.5j]], np.array([1.0, 2.0], dtype=complex)])
def test_complex_input_is_refused_not_truncated(value):
    with pytest.raises(errors.ModelError, match=r"^x0: expected real entries, got a complex "
                                                r"array"):
        v.as_float_array("x0", value)
    with pytest.raises(errors.ModelError, match=r"^x0: expected real entries"):
        v.as_vector("x0", value)


@pytest.mark.parametrize("value", ["1.5", ["1", "2"], np.array(["a"])])
def test_strings_are_refused_not_parsed(value):
    with pytest.raises(errors.ModelError, match=r"^q: expected a real numeric array, got "
                                                r"strings"):
        v.as_float_array("q", value)


@pytest.mark.parametrize("value", ["2", 1j, np.complex128(1.0), True, None, [1.0, 2.0],
                                   np.ones(2)])
def test_scalar_checks_name_the_argument(value):
    with pytest.raises(errors.ModelError, match=r"^tol: expected a real number, got"):
        v.check_positive("tol", value)
    with pytest.raises(errors.ModelError, match=r"^e: expected a real number, got"):
        v.check_in_interval("e", value, 0.0, 1.0)


def test_scalar_and_integer_checks():
    assert v.check_positive("h", np.array([0.5])) == 0.5   # a one-element array is its value
    assert v.check_in_interval("omega", 1.0, 0.0, 2.0, open_interval=True) == 1.0
    with pytest.raises(errors.ModelError, match=r"^omega: expected a value in \(0.0, 2.0\), "
                                                r"got 2.0"):
        v.check_in_interval("omega", 2.0, 0.0, 2.0, open_interval=True)
    assert v.check_integer("n", np.int32(3), minimum=1) == 3
    assert v.check_integer("n", 1e4, minimum=1) == 10_000
    for bad in (2.7, "3", True, np.nan, None, [3]):
        with pytest.raises(errors.ModelError, match=r"^n: expected an integer >= 1, got"):
            v.check_integer("n", bad, minimum=1)
    with pytest.raises(errors.DimensionError, match=r"^dim: expected an integer >= 1, got 0"):
        v.check_integer("dim", 0, minimum=1, error=errors.DimensionError)


BENCH_KEYS = {"scenario", "size", "ours_s_per_solve", "reference", "reference_s_per_solve",
              "ratio", "accuracy"}


def test_bench_lcp_quick_json_is_one_object_per_line(monkeypatch):
    # ~20 s with Siconos installed (its subprocess included), numba cache warm. The bar
    # normally waits 2 s; a fast machine may finish first, so it is asked for at once.
    monkeypatch.setattr("nscontrol._progress.ITER_DELAY", 0.0)
    result = CliRunner().invoke(main, ["bench", "lcp", "--json", "--quick"])
    assert result.exit_code == 0, result.output
    lines = [line for line in result.stdout.splitlines() if line.strip()]
    records = [json.loads(line) for line in lines]          # every stdout line is JSON
    assert len(records) >= 10
    scenarios = set()
    for r in records:
        assert isinstance(r, dict) and BENCH_KEYS <= set(r), set(r) ^ BENCH_KEYS
        assert isinstance(r["scenario"], str) and r["scenario"].startswith("lcp/")
        assert isinstance(r["size"], int) and r["ours_s_per_solve"] > 0.0
        assert isinstance(r["accuracy"], dict) and r["accuracy"]["ours_status"] == "solved"
        if r["reference"] is None:
            assert r["ratio"] is None and r["reference_s_per_solve"] is None
        else:
            assert r["ratio"] == pytest.approx(r["reference_s_per_solve"]
                                               / r["ours_s_per_solve"])
        scenarios.add(r["scenario"])
    assert {"lcp/stack/banded", "lcp/impact/banded", "lcp/impact-mid/banded"} <= scenarios
    impact = [r for r in records if r["scenario"] == "lcp/impact/banded"]
    assert all(r["accuracy"]["ours_iterations"] == 0 for r in impact)
    assert "bench lcp" in result.stderr                  # the progress bar, on stderr


def test_a_chapter_with_one_example_names_it():
    from nscontrol.examples import all_examples, get_example

    chapters: dict[str, list[str]] = {}
    for ex in all_examples():
        chapters.setdefault(ex.chapter, []).append(ex.name)
    single = [c for c, names in chapters.items() if len(names) == 1]
    several = [c for c, names in chapters.items() if len(names) > 1]
    assert "ch08" in single and several   # as `nscontrol list` shows them today
    assert get_example("ch08").name == "ch08-lure-observer"
    with pytest.raises(KeyError, match="several examples"):
        get_example(several[0])
