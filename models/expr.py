"""Safe arithmetic expressions of distance for error rates (BER/PER as a function of metres).

Scene files come from users and are read by a daemon, so an expression must never reach Python's
``eval``.  This module tokenises and parses the small grammar below itself and compiles the tree
into nested closures.  Everything is float arithmetic, so nothing can build a huge integer; constant
sub-trees are folded at load time, which turns ``9^9^9`` into a load-time error instead of a
surprise in the middle of a run.

Grammar (precedence low to high)::

    expr   := term (('+' | '-') term)*
    term   := unary (('*' | '/') unary)*
    unary  := ('+' | '-') unary | power
    power  := atom (('^' | '**') unary)?          # right-associative, binds tighter than unary minus on its left
    atom   := NUMBER | NAME | NAME '(' expr (',' expr)* ')' | '(' expr ')'

Variables: ``d`` and its alias ``m`` (UWSim-NET's exprtk expressions use ``m``).
Functions: exp log log10 sqrt pow min max abs.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Callable

__all__ = ["ExprError", "Expression", "compile_expression"]

MAX_LENGTH = 1000
MAX_DEPTH = 64
MAX_EXPONENT = 1000.0
VARIABLES = frozenset({"d", "m"})


class ExprError(ValueError):
    """An expression that cannot be accepted; the message says where and why."""


def _safe_pow(base: float, exponent: float) -> float:
    try:
        return math.pow(base, exponent)
    except OverflowError:
        return math.inf
    except ValueError:  # negative base with a fractional exponent, 0 ** negative
        return math.nan


def _safe_exp(x: float) -> float:
    try:
        return math.exp(x)
    except OverflowError:
        return math.inf


def _safe_log(x: float, log: Callable[[float], float] = math.log) -> float:
    if x > 0:
        return log(x)
    return -math.inf if x == 0 else math.nan


def _safe_div(a: float, b: float) -> float:
    if b == 0:
        return math.nan if a == 0 else math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def _safe_sqrt(x: float) -> float:
    return math.sqrt(x) if x >= 0 else math.nan


# name -> (callable, minimum arity, maximum arity)
FUNCTIONS: dict[str, tuple[Callable[..., float], int, int]] = {
    "exp": (_safe_exp, 1, 1),
    "log": (_safe_log, 1, 1),
    "log10": (lambda x: _safe_log(x, math.log10), 1, 1),
    "sqrt": (_safe_sqrt, 1, 1),
    "pow": (_safe_pow, 2, 2),
    "min": (min, 2, 16),
    "max": (max, 2, 16),
    "abs": (abs, 1, 1),
}

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z_0-9]*)"
    r"|(?P<op>\*\*|[-+*/^(),]))"
)


@dataclass(frozen=True)
class _Token:
    kind: str  # num | name | op | end
    text: str
    pos: int


def _tokenise(text: str) -> list[_Token]:
    tokens: list[_Token] = []
    pos = 0
    while pos < len(text):
        if text[pos:].strip() == "":
            break
        match = _TOKEN.match(text, pos)
        if not match:
            raise ExprError(f"unexpected character {text[pos:].lstrip()[0]!r} at column {pos + 1}")
        kind = match.lastgroup
        assert kind is not None
        tokens.append(_Token(kind, match.group(kind), match.start(kind)))
        pos = match.end()
    tokens.append(_Token("end", "", len(text)))
    return tokens


# A compiled node is (closure, constant-or-None): constants are folded eagerly.
_Node = tuple[Callable[[float], float], "float | None"]


def _const(value: float) -> _Node:
    return (lambda d: value), value


class _Parser:
    def __init__(self, text: str):
        self.tokens = _tokenise(text)
        self.index = 0
        self.depth = 0

    @property
    def current(self) -> _Token:
        return self.tokens[self.index]

    def take(self) -> _Token:
        token = self.tokens[self.index]
        self.index += 1
        return token

    def expect(self, text: str) -> None:
        token = self.take()
        if token.text != text:
            found = "end of expression" if token.kind == "end" else repr(token.text)
            raise ExprError(f"expected {text!r} at column {token.pos + 1}, found {found}")

    def parse(self) -> _Node:
        node = self.expr()
        token = self.current
        if token.kind != "end":
            raise ExprError(f"unexpected {token.text!r} at column {token.pos + 1}")
        return node

    def _descend(self) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExprError(f"expression nested deeper than {MAX_DEPTH} levels")

    def expr(self) -> _Node:
        node = self.term()
        while self.current.text in ("+", "-"):
            op = self.take().text
            node = _binary(op, node, self.term())
        return node

    def term(self) -> _Node:
        node = self.unary()
        while self.current.text in ("*", "/"):
            op = self.take().text
            node = _binary(op, node, self.unary())
        return node

    def unary(self) -> _Node:
        if self.current.text in ("+", "-"):
            op = self.take().text
            self._descend()
            operand = self.unary()
            self.depth -= 1
            if op == "+":
                return operand
            fn, const = operand
            return _const(-const) if const is not None else ((lambda d: -fn(d)), None)
        return self.power()

    def power(self) -> _Node:
        base = self.atom()
        if self.current.text in ("^", "**"):
            self.take()
            self._descend()
            exponent = self.unary()
            self.depth -= 1
            return _binary("^", base, exponent)
        return base

    def atom(self) -> _Node:
        token = self.take()
        if token.kind == "num":
            value = float(token.text)
            if math.isinf(value):
                raise ExprError(f"number {token.text} at column {token.pos + 1} is too large")
            return _const(value)
        if token.kind == "name":
            if self.current.text == "(":
                return self.call(token)
            if token.text in VARIABLES:
                return (lambda d: d), None
            if token.text in FUNCTIONS:
                raise ExprError(f"function {token.text!r} at column {token.pos + 1} needs arguments in parentheses")
            raise ExprError(
                f"unknown name {token.text!r} at column {token.pos + 1} (the variable is d or m; "
                f"functions: {', '.join(sorted(FUNCTIONS))})"
            )
        if token.text == "(":
            self._descend()
            node = self.expr()
            self.depth -= 1
            self.expect(")")
            return node
        found = "end of expression" if token.kind == "end" else repr(token.text)
        raise ExprError(f"expected a number, d, a function or '(' at column {token.pos + 1}, found {found}")

    def call(self, name: _Token) -> _Node:
        if name.text not in FUNCTIONS:
            raise ExprError(f"unknown function {name.text!r} at column {name.pos + 1}")
        fn, low, high = FUNCTIONS[name.text]
        self.expect("(")
        self._descend()
        args = [self.expr()]
        while self.current.text == ",":
            self.take()
            args.append(self.expr())
        self.depth -= 1
        self.expect(")")
        if not low <= len(args) <= high:
            wanted = str(low) if low == high else f"{low} to {high}"
            raise ExprError(f"{name.text}() at column {name.pos + 1} takes {wanted} arguments, got {len(args)}")
        if all(const is not None for _, const in args):
            return _folded(fn(*(const for _, const in args)), name.text)
        closures = [closure for closure, _ in args]
        if len(closures) == 1:
            (a,) = closures
            return (lambda d: fn(a(d))), None
        if len(closures) == 2:
            a, b = closures
            return (lambda d: fn(a(d), b(d))), None
        return (lambda d: fn(*(c(d) for c in closures))), None


def _folded(value: float, what: str) -> _Node:
    if math.isinf(value) or math.isnan(value):
        raise ExprError(f"constant part {what} evaluates to {value} (overflow or undefined)")
    return _const(value)


_OPS: dict[str, Callable[[float, float], float]] = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": lambda a, b: a * b,
    "/": _safe_div,
    "^": _safe_pow,
}


def _binary(op: str, left: _Node, right: _Node) -> _Node:
    lf, lc = left
    rf, rc = right
    fn = _OPS[op]
    if lc is not None and rc is not None:
        try:
            value = fn(lc, rc)
        except OverflowError:
            value = math.inf
        return _folded(value, f"'{lc:g} {op} {rc:g}'")
    # Specialise the common shapes so that evaluation is one or two calls deep.
    if op == "^" and rc is not None:
        if abs(rc) > MAX_EXPONENT:
            raise ExprError(f"exponent {rc:g} is beyond ±{MAX_EXPONENT:g}; no error-rate curve needs it")
        return (lambda d: _safe_pow(lf(d), rc)), None
    if op == "*" and lc is not None:
        return (lambda d: lc * rf(d)), None
    if op == "*" and rc is not None:
        return (lambda d: lf(d) * rc), None
    return (lambda d: fn(lf(d), rf(d))), None


class Expression:
    """A compiled expression of one variable (distance in metres)."""

    __slots__ = ("text", "_fn", "constant")

    def __init__(self, text: str, fn: Callable[[float], float], constant: float | None):
        self.text = text
        self._fn = fn
        self.constant = constant

    def __call__(self, d: float) -> float:
        return self._fn(float(d))

    def rate(self, d: float) -> float:
        """The value at ``d`` as a probability: clamped to [0, 1]; undefined (NaN) counts as certain loss."""
        value = self._fn(float(d))
        if value != value:  # NaN
            return 1.0
        return 0.0 if value < 0.0 else 1.0 if value > 1.0 else value

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"


def compile_expression(text: object) -> Expression:
    """Parse ``text`` (a string or a number) into an :class:`Expression`, or raise :class:`ExprError`."""
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ExprError(f"an error-rate expression must be a string or a number, not {type(text).__name__}")
    if isinstance(text, str):
        source = text
    else:
        try:
            source = repr(float(text))
        except OverflowError:  # an int beyond a float's range (YAML reads 400 nines as one)
            raise ExprError("the number is too large (beyond a float's ±1.8e308)") from None
    if len(source) > MAX_LENGTH:
        raise ExprError(f"expression longer than {MAX_LENGTH} characters")
    if not source.strip():
        raise ExprError("empty expression")
    fn, constant = _Parser(source).parse()
    return Expression(source, fn, constant)
