"""The switching and implicit-Euler methods read their options once into a frozen dataclass
(issue 30): unknown names and bad values are refused there, and nothing past the parser
reads the raw ``options`` mapping. Also the cheap progress bar and the per-system setup of
implicit Euler, which the fixed cost of a call relies on."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import nscontrol
from nscontrol import simulate
from nscontrol._progress import TimeProgress
from nscontrol.errors import ModelError
from nscontrol.laws.relay import Relay
from nscontrol.simulate.implicit_euler import ImplicitEulerOptions
from nscontrol.simulate.switching._run import SwitchingOptions
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem

SIMULATE = Path(nscontrol.__file__).resolve().parent / "simulate"
TYPED = ("switching/__init__.py", "switching/_run.py", "switching/_pwa.py",
         "switching/_filippov.py", "switching/_pwm.py", "implicit_euler/__init__.py",
         "implicit_euler/_options.py", "implicit_euler/_stepper.py", "implicit_euler/_steps.py")


def _lure() -> LureSystem:
    return LureSystem([[0.0, 1.0], [-1.0, -0.1]], [[0.0], [1.0]], [[1.0, 1.0]], Relay(1.0))


def test_options_are_parsed_into_frozen_records() -> None:
    sw = SwitchingOptions.parse({"rtol": 1e-8, "n_samples": 5})
    assert (sw.rtol, sw.n_samples, sw.atol, sw.max_events) == (1e-8, 5, 1e-13, 1_000_000)
    ie = ImplicitEulerOptions.parse({"h": 0.01, "theta": 0.5, "signals": ["z"]})
    assert (ie.h, ie.theta, ie.signals, ie.blocks) == (0.01, 0.5, frozenset({"z"}), None)
    for record in (sw, ie):
        with pytest.raises(dataclasses.FrozenInstanceError):
            record.u = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(("parse", "options", "match"), [
    (SwitchingOptions.parse, {"rtl": 1e-8}, r"switching: unknown option\(s\) \['rtl'\]"),
    (SwitchingOptions.parse, {"controller": 1}, "PWMController"),
    (SwitchingOptions.parse, {"rtol": -1.0}, "rtol: expected a finite number > 0"),
    (SwitchingOptions.parse, {"n_samples": 1}, "n_samples"),
    (SwitchingOptions.parse, {"min_rel_step": 1.0}, "min_rel_step"),
    (SwitchingOptions.parse, {"t_eval": [1.0, 0.0]}, "t_eval: expected an increasing"),
    (SwitchingOptions.parse, {"progress": "no"}, "progress"),
    (ImplicitEulerOptions.parse, {}, "h: implicit_euler needs a step"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "thta": 1.0}, r"unknown option\(s\) \['thta'\]"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "theta": 0.2}, "theta"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "record_every": 0}, "record_every"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "signals": ["q"]}, r"signals: unknown name"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "controller": abs},
     r"unknown option\(s\) \['controller'\]"),
    (ImplicitEulerOptions.parse, {"h": 0.1, "blocks": abs}, "blocks: expected the BlockRunner"),
])
def test_bad_options_are_refused_by_the_parser(parse, options, match) -> None:
    with pytest.raises(ModelError, match=match):
        parse(options)


def test_no_code_past_the_parser_reads_the_raw_options() -> None:
    """``options.get`` / ``options[...]`` appear only in the ``parse`` classmethods."""
    offenders = []
    for name in TYPED:
        tree = ast.parse((SIMULATE / name).read_text(encoding="utf-8"))
        parse_nodes = {id(n) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)
                       and f.name == "parse" for n in ast.walk(f)}
        for node in ast.walk(tree):
            if id(node) in parse_nodes:
                continue
            if isinstance(node, ast.Attribute) and node.attr == "get" and \
                    isinstance(node.value, ast.Name) and node.value.id == "options":
                offenders.append(f"{name}:{node.lineno} options.get")
            if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and \
                    node.value.id == "options":
                offenders.append(f"{name}:{node.lineno} options[...]")
    assert not offenders, offenders


def test_implicit_euler_setup_is_per_system_and_step() -> None:
    """The kept setup is keyed by the step: a second step size on the same system gets its
    own matrices (the stats and the states differ), and an equal call gives equal results."""
    lure = _lure()
    a = simulate(lure, [1.0, 0.0], (0.0, 0.1), h=0.01)
    b = simulate(lure, [1.0, 0.0], (0.0, 0.1), h=0.02)
    c = simulate(lure, [1.0, 0.0], (0.0, 0.1), h=0.01)
    d = simulate(_lure(), [1.0, 0.0], (0.0, 0.1), h=0.01)   # a fresh system: no kept setup
    assert (a.stats["h"], b.stats["h"]) == (0.01, 0.02)
    assert len(a.t) == 11 and len(b.t) == 6
    np.testing.assert_array_equal(a.x, c.x)
    np.testing.assert_array_equal(a.x, d.x)
    assert not np.allclose(a.x[-1], b.x[-1], rtol=0.0, atol=1e-6)   # O(h) apart


def test_pwa_modes_follow_the_input_object() -> None:
    """A PWA system's kept modes are per input object: another input is another flow."""
    from nscontrol.numerics.lti import Exosystem

    pwa = PiecewiseAffineSystem.bimodal([[0.0, 1.0], [-2.0, -0.1]], [[0.0, 1.0], [-1.0, -0.1]],
                                        [1.0, 0.0], E=[[0.0], [1.0]])
    free = simulate(pwa, [1.0, 0.0], (0.0, 1.0), n_samples=3)
    pushed = simulate(pwa, [1.0, 0.0], (0.0, 1.0), n_samples=3, u=Exosystem.constant([1.0]))
    again = simulate(pwa, [1.0, 0.0], (0.0, 1.0), n_samples=3)
    np.testing.assert_array_equal(free.x, again.x)
    assert pushed.x[-1, 1] - free.x[-1, 1] > 0.5   # ∫ u over one second, little damped


def test_progress_bar_is_built_only_once_due(monkeypatch) -> None:
    """No tqdm for a run shorter than the delay; past it, the bar appears with the run's
    elapsed time; ``progress=False`` never shows one."""
    clock = [100.0]
    monkeypatch.setattr("nscontrol._progress.time.perf_counter", lambda: clock[0])
    bar = TimeProgress(0.0, 1.0, delay=2.0)
    bar.update(0.5)
    assert bar._bar is None
    clock[0] = 103.0
    bar.update(0.6)
    assert bar._bar is not None and bar._bar.start_t == 100.0 and bar._bar.n == 600
    bar.close()
    off = TimeProgress(0.0, 1.0, enable=False, delay=0.0)
    clock[0] = 200.0
    off.update(0.5)
    assert off._bar is None
