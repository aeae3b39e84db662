"""``record(arr, DTYPE)``: a compiled kernel reads and writes a flat float64 array by the
field names of a structured dtype, exactly as NumPy lays the record out."""

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from nscontrol.systems._feedback_kernels import record

REC = np.dtype([("a", np.float64), ("b", np.float64), ("c", np.float64)])


@njit(cache=False)
def _read(p):
    r = record(p, REC)
    return r.a, r.b, r.c


@njit(cache=False)
def _write(p, value):
    record(p, REC).b = value


def test_fields_are_numpys_layout_read_and_written_in_place():
    rec = np.zeros(1, REC)
    rec["a"], rec["b"], rec["c"] = 1.5, -2.0, 7.25
    flat = rec.view(np.float64)
    assert _read(flat) == (1.5, -2.0, 7.25)
    _write(flat, 3.0)
    assert rec["b"][0] == 3.0 and rec["a"][0] == 1.5 and rec["c"][0] == 7.25


def test_a_longer_array_holds_the_record_at_its_head():
    flat = np.arange(5.0)
    assert _read(flat) == (0.0, 1.0, 2.0)
    _write(flat, 9.0)
    assert flat.tolist() == [0.0, 9.0, 2.0, 3.0, 4.0]


def test_only_contiguous_float64_arrays_are_accepted():
    with pytest.raises(TypingError):
        _read(np.arange(3))                      # int64
    with pytest.raises(TypingError):
        _read(np.arange(6.0)[::2])               # not contiguous
