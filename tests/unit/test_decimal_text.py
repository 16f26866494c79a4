"""The whole-line decimal parser (scan2morph.io.decimal_text) against numpy's and Python's own."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io import read_abs
from scan2morph.io.decimal_text import MAX_DIGITS, parse_decimals


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def _random_tokens(rng, n: int) -> list[str]:
    """Plain decimals of 1 to MAX_DIGITS digits, the point anywhere or absent, half negative."""
    out = []
    for _ in range(n):
        digits = "".join(rng.choice(list("0123456789"), int(rng.integers(1, MAX_DIGITS + 1))))
        cut = int(rng.integers(0, len(digits) + 1))
        token = digits[:cut] + "." + digits[cut:] if rng.random() < 0.8 else digits
        out.append("-" + token if rng.random() < 0.5 else token)
    return out


def test_bit_identical_to_loadtxt_and_float():
    rng = np.random.default_rng(7)
    tokens = _random_tokens(rng, 20000)
    line = "  " + " ".join(tokens) + " "
    got = parse_decimals(line)
    assert np.array_equal(_bits(got), _bits([float(t) for t in tokens]))
    assert np.array_equal(_bits(got), _bits(np.loadtxt([line], ndmin=1)))


def test_frgc_style_values():
    # "%.6f" as the writer and FRGC give them, including the no-data placeholder and -0
    values = np.array([-999999.0, -0.0, 0.0, 1e-6, 123.456789, -87.000001, 0.1, 2.675])
    line = " ".join(f"{v:.6f}" for v in values)
    assert np.array_equal(_bits(parse_decimals(line)), _bits(np.loadtxt([line])))
    assert np.signbit(parse_decimals("-0.000000 -0"))[0:2].all()


@pytest.mark.parametrize("token", ["-.5", "3.", ".25", "007", "0", "-0"])
def test_plain_forms_python_accepts(token):
    assert _bits(parse_decimals(f"1 {token}"))[1] == _bits(float(token))


@pytest.mark.parametrize(
    "line",
    [
        "1e5 2",  # an exponent
        "nan 1",
        "+1",
        "1\t2",  # another white space
        "1 - 2",  # a sign alone
        "1-2",  # a sign inside a token
        "--1",
        "1..2",
        "1.2.3",
        ".",
        "-.",
        "1" * (MAX_DIGITS + 1),  # more digits than a float64 holds exactly
        "1 x 2",
        "1 \u00e9",  # not ASCII
    ],
)
def test_other_text_is_left_to_the_caller(line):
    assert parse_decimals(line) is None


def test_empty_line():
    assert parse_decimals("").shape == (0,)
    assert parse_decimals("   ").shape == (0,)


def _write_abs_text(path, lines, rows=2, cols=3):
    path.write_text(f"{rows} rows\n{cols} columns\npixels (flag X Y Z):\n" + "\n".join(lines))


def test_read_abs_mixed_forms_equal_loadtxt(tmp_path):
    """A line the fast path leaves (exponents, a '+') is read token by token: same values."""
    lines = ["1 1 0 1 1 1", "1.5 -2 3e1 4.25 +5 -999999", "1 2 3 4 5 -999999", "7 8 9 10 11 0.5"]
    _write_abs_text(tmp_path / "m.abs", lines)
    xyz = read_abs(tmp_path / "m.abs")
    cols = [np.loadtxt([ln]) for ln in lines[1:]]
    expect = np.stack(cols, axis=-1).reshape(2, 3, 3)
    expect[0, 2] = np.nan  # flag 0
    assert np.array_equal(_bits(xyz), _bits(expect))


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("1 2 3 4 5", r"line 'X': expected 2\*3 = 6 values, got 5"),
        ("1 2 3 4 5 6 7", r"line 'X': expected 2\*3 = 6 values, got 7"),
        ("1 2 x3 4 5 6", r"line 'X': non-numeric value 'x3'"),
        ("1 2 3-4 4 5 6", r"line 'X': non-numeric value '3-4'"),
        ("1 2 3..4 4 5 6", r"line 'X': non-numeric value '3..4'"),
    ],
)
def test_read_abs_bad_values_name_file_and_line(tmp_path, line, match):
    _write_abs_text(tmp_path / "bad.abs", ["1 1 1 1 1 1", line, "1 2 3 4 5 6", "1 2 3 4 5 6"])
    with pytest.raises(InputError, match=match) as err:
        read_abs(tmp_path / "bad.abs")
    assert "bad.abs" in str(err.value)
