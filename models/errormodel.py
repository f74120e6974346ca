"""Loss of a frame on a good (collision-free) arrival, from a rate expression of distance."""

from __future__ import annotations

import math

from .expr import Expression, compile_expression

UNITS = ("bit", "byte", "packet")


class ErrorModel:
    """``unit: bit`` gives PER = 1 − (1 − r)^(8L), ``byte`` 1 − (1 − r)^L, ``packet`` r, with r the
    expression at distance d, clamped to [0, 1].  Computed through log1p/expm1 because the rates of
    interest (UWSim-NET's 6e-13·d^13.7 at short range) vanish in plain ``1 - r``."""

    __slots__ = ("unit", "expression", "_bits_per_byte", "constant_zero")
    sinr = False
    """(An expression of distance has no received power: arrivals that overlap collide.)"""
    capture = 0.0

    def __init__(self, unit: str, expression: Expression | str | float):
        if unit not in UNITS:
            raise ValueError(f"unit must be one of {', '.join(UNITS)}, not {unit!r}")
        self.unit = unit
        self.expression = expression if isinstance(expression, Expression) else compile_expression(expression)
        self._bits_per_byte = {"bit": 8, "byte": 1, "packet": 0}[unit]
        self.constant_zero = self.expression.constant is not None and self.expression.constant <= 0

    def per(self, d: float, size: int) -> float:
        """Probability that a frame of ``size`` bytes is lost at distance ``d``."""
        if self.constant_zero:
            return 0.0
        r = self.expression.rate(d)
        if self._bits_per_byte == 0 or r == 0.0 or r == 1.0:
            return r
        return -math.expm1(self._bits_per_byte * size * math.log1p(-r))

    def __reduce__(self):
        """Pickled as its source: the daemon validates a reloaded scene in a child process."""
        return (ErrorModel, (self.unit, self.expression.text))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ErrorModel):
            return NotImplemented
        return (self.unit, self.expression.text) == (other.unit, other.expression.text)

    def __hash__(self) -> int:
        return hash((self.unit, self.expression.text))

    def __repr__(self) -> str:
        return f"ErrorModel({self.unit}, {self.expression.text!r})"


NO_ERRORS = ErrorModel("packet", "0")
