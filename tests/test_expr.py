"""The safe error-rate expression evaluator: exact values, precedence, and hostile input refused."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hilgate.models.errormodel import ErrorModel
from hilgate.models.expr import ExprError, compile_expression


def test_uwsim_net_expression_loads_as_written():
    e = compile_expression("6e-13*m^13.7")
    assert e(2.0) == 6e-13 * 2.0 ** 13.7
    assert compile_expression("6e-13 * d^13.7")(3.5) == 6e-13 * 3.5 ** 13.7
    assert compile_expression("6e-13*m**13.7")(1.0) == 6e-13


@pytest.mark.parametrize("text,d,value", [
    ("-2^2", 0, -4.0),
    ("2^3^2", 0, 512.0),
    ("2^-1", 0, 0.5),
    ("1 + 2 * 3", 0, 7.0),
    ("(1 + 2) * 3", 0, 9.0),
    ("10 / 4 / 5", 0, 0.5),
    ("d - m", 7, 0.0),
    ("exp(0) + log(1) + log10(100) + sqrt(16)", 0, 7.0),
    ("pow(d, 2) + abs(-3)", 3, 12.0),
    ("min(d, 1, 0.5) + max(d, 2)", 3, 3.5),
    ("0.01*m", 20, 0.2),
    (".5e1", 0, 5.0),
    ("0", 100, 0.0),
])
def test_arithmetic(text, d, value):
    assert compile_expression(text)(d) == pytest.approx(value, abs=1e-15)


def test_numbers_are_accepted_as_expressions():
    assert compile_expression(0)(5) == 0.0
    assert compile_expression(0.25)(5) == 0.25


@pytest.mark.parametrize("text", [
    "__import__('os')",
    "__import__",
    "d.real",
    "().__class__",
    "exec('1')",
    "eval('1')",
    "open('/etc/passwd')",
    "lambda: 1",
    "d if d else 1",
    "[1, 2]",
    "d; 1",
    "9**9**9",
    "9^9^9",
    "10^400",
    "1e400",
    "exp(1000)",
    "d^1e6",
    "d^(2)^(600)",
    "x * 2",
    "sqrt",
    "sqrt(1, 2)",
    "min(1)",
    "",
    "   ",
    "2 +",
    "(d",
    "d)",
    "1/0",
    "(" * 100 + "d" + ")" * 100,
    "-" * 200 + "d",
    "d" + "+d" * 600,
])
def test_hostile_or_broken_input_is_refused_with_a_clear_error(text):
    with pytest.raises(ExprError) as info:
        compile_expression(text)
    assert str(info.value)


def test_non_text_is_refused():
    for value in (None, True, [1], {"a": 1}):
        with pytest.raises(ExprError):
            compile_expression(value)


def test_rate_is_a_probability():
    assert compile_expression("d").rate(-1) == 0.0
    assert compile_expression("d").rate(5) == 1.0
    assert compile_expression("log(d)").rate(-1) == 1.0  # undefined counts as certain loss
    assert compile_expression("1/d").rate(0) == 1.0


def test_runtime_overflow_is_not_an_exception():
    e = compile_expression("exp(d)")
    assert e(1e6) == math.inf
    assert e.rate(1e6) == 1.0


def test_per_from_ber_uses_the_unit():
    r = 1e-3
    assert ErrorModel("bit", str(r)).per(0, 10) == pytest.approx(1 - (1 - r) ** 80, rel=1e-12)
    assert ErrorModel("byte", str(r)).per(0, 10) == pytest.approx(1 - (1 - r) ** 10, rel=1e-12)
    assert ErrorModel("packet", str(r)).per(0, 10) == r
    # tiny BERs keep their precision (1 - r rounds to 1 for r < 1e-16)
    assert ErrorModel("bit", "6e-13 * d^13.7").per(0.8, 20) == pytest.approx(160 * 6e-13 * 0.8 ** 13.7, rel=1e-9)


_alphabet = st.sampled_from(list("0123456789.eE+-*/^(),dmx_ ") + ["exp", "log", "sqrt", "min", "**", "__", "import"])


@settings(max_examples=2000, deadline=None)
@given(st.lists(_alphabet, max_size=30).map("".join))
def test_fuzz_only_expr_errors_and_evaluation_never_raises(text):
    try:
        expression = compile_expression(text)
    except ExprError:
        return
    for d in (0.0, 0.5, 1.0, 6.0, 1e4, -1.0):
        value = expression(d)
        assert isinstance(value, float)
        assert 0.0 <= expression.rate(d) <= 1.0


def test_integers_beyond_a_float_are_refused_not_overflowing():
    with pytest.raises(ExprError, match="too large"):
        compile_expression(10 ** 400)
    with pytest.raises(ExprError, match="too large"):
        compile_expression(-(10 ** 5000))
    with pytest.raises(ExprError, match="too large"):
        compile_expression("9" * 400)
