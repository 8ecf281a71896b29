"""``trep.Spline``: a piecewise polynomial through points ``[x, y]``, ``[x, y, dy]`` or
``[x, y, dy, ddy]`` (``None`` for a derivative left free), with its first two derivatives,
as trep 1.0.2 builds it (checked against trep itself: python/tests/fixtures/trep-api.json).

How the curve is chosen (docs/python.md, "Spline"):

* Between points the curve is a polynomial in ``t = x − x_i`` that passes through both
  points; where a point gives no derivative the neighbouring pieces share their slope and
  curvature there (a cubic spline), and a given derivative is met by both pieces.
* Too few conditions (trep's "not enough constraints"): the second derivative is taken to be
  zero at the first point if it is free there, then at the last — the natural cubic spline
  for points without derivatives.
* Too many: a point that gives both derivatives splits the curve into independent parts,
  and an end of a part that gives both raises the degree of the piece beside it by one (up
  to a quintic). A surplus that comes from an interior point giving only one derivative is
  placed where trep places it (the nearest end of the run cancels it first; see
  ``_raised``).
* Outside the points the curve continues as the quadratic that meets the end point's value,
  slope and curvature.
"""
from __future__ import annotations

import bisect
import math
from typing import Any, List, Optional, Sequence

import numpy as np

__all__ = ["Spline"]


def _number(x: Any, where: str) -> float:
    value = float(x)
    if not np.isfinite(value):
        raise ValueError(f"Spline: {where} is {value}; every number must be finite")
    return value


def _parse(points: Sequence[Any]):
    """``(x, y, dy, ddy)`` as lists, ``None`` where a derivative is free."""
    if len(points) < 2:
        raise ValueError(f"Spline: needs at least two points, got {len(points)}")
    xs, ys, dys, ddys = [], [], [], []
    for k, p in enumerate(points):
        p = list(p)
        if not 2 <= len(p) <= 4:
            raise ValueError(f"Spline: point {k} has {len(p)} numbers; give [x, y], "
                             "[x, y, dy] or [x, y, dy, ddy]")
        p += [None] * (4 - len(p))
        xs.append(_number(p[0], f"point {k}'s x"))
        ys.append(_number(p[1], f"point {k}'s y"))
        dys.append(None if p[2] is None else _number(p[2], f"point {k}'s dy"))
        ddys.append(None if p[3] is None else _number(p[3], f"point {k}'s ddy"))
        if k and xs[k] <= xs[k - 1]:
            raise ValueError(f"Spline: the points' x must increase; point {k} has x = "
                             f"{xs[k]!r} after {xs[k - 1]!r}")
    return xs, ys, dys, ddys


def _raised(dys: List[Optional[float]], ddys: List[Optional[float]]) -> List[int]:
    """How far each piece's degree is raised above a cubic so that the conditions and the
    coefficients are as many (the rules in the module's documentation)."""
    n = len(dys)
    given = [(dys[j] is not None) + (ddys[j] is not None) for j in range(n)]
    raised = [0] * (n - 1)
    splits = [0] + [j for j in range(1, n - 1) if given[j] == 2] + [n - 1]
    for a, b in zip(splits, splits[1:]):
        # Surplus of each point of the part over what a cubic spline takes: an end takes one
        # derivative, an interior point none.
        items = []  # (point, surplus, piece it raises)
        for j in range(a, b + 1):
            if j in (a, b):
                extra = (2 if (j != 0 and j == a) or (j != n - 1 and j == b) else given[j]) - 1
                piece = j if j == a else j - 1
            else:
                # An interior point's surplus raises the piece before it, or the one after
                # where the one before is raised already.
                taken = {it[2] for it in items if it[1] > 0}
                extra, piece = given[j], (j if j - 1 in taken else j - 1)
            if extra:
                items.append([j, extra, piece])
        for neg in [it for it in items if it[1] < 0]:
            while neg[1] < 0:
                positives = [it for it in items if it[1] > 0]
                if not positives:
                    break
                nearest = min(positives, key=lambda it: abs(it[0] - neg[0]))
                nearest[1] -= 1
                neg[1] += 1
        for _, extra, piece in items:
            if extra > 0:
                raised[piece] += extra
    return raised


class Spline:
    """A curve through ``points`` with its value ``y(x)``, slope ``dy(x)`` and curvature
    ``ddy(x)`` (trep's ``Spline``)."""

    def __init__(self, points: Sequence[Any]):
        xs, ys, dys, ddys = _parse(points)
        n = len(xs)
        # Too few conditions: zero curvature at the first point, then at the last.
        surplus = sum(g is not None for g in dys + ddys) - 2
        for end in (0, n - 1):
            if surplus < 0 and ddys[end] is None:
                ddys[end] = 0.0
                surplus += 1
        self._x = np.array(xs)
        self._y = np.array(ys)
        self._pieces = self._solve(xs, ys, dys, ddys, _raised(dys, ddys))
        self._xs = [float(x) for x in xs]
        # Each piece's coefficients and those of its first two derivatives, lowest first.
        self._derived = [[[math.perm(k, order) * float(c[k]) for k in range(order, len(c))]
                          for c in self._pieces] for order in range(3)]
        self._ends = tuple(tuple(self._piece_at(i, t, o) for o in range(3))
                           for i, t in ((0, 0.0), (n - 2, xs[-1] - xs[-2])))

    @staticmethod
    def _solve(xs, ys, dys, ddys, raised) -> List[np.ndarray]:
        """Every piece's coefficients (lowest power first), from one square linear system."""
        n = len(xs)
        degrees = [3 + r for r in raised]
        start = np.concatenate([[0], np.cumsum([d + 1 for d in degrees])])
        rows: List[np.ndarray] = []
        rhs: List[float] = []

        def derivative_row(i: int, order: int, t: float) -> np.ndarray:
            row = np.zeros(start[-1])
            for p in range(order, degrees[i] + 1):
                factor = float(np.prod(range(p - order + 1, p + 1)))
                row[start[i] + p] = factor * t ** (p - order)
            return row

        for i in range(n - 1):
            h = xs[i + 1] - xs[i]
            rows += [derivative_row(i, 0, 0.0), derivative_row(i, 0, h)]
            rhs += [ys[i], ys[i + 1]]
        for j in range(n):
            for order, given in ((1, dys[j]), (2, ddys[j])):
                left = j - 1 if j > 0 else None
                right = j if j < n - 1 else None
                if given is not None:
                    for i, t in ((left, None), (right, 0.0)):
                        if i is not None:
                            at = xs[j] - xs[i] if t is None else t
                            rows.append(derivative_row(i, order, at))
                            rhs.append(given)
                elif left is not None and right is not None:
                    rows.append(derivative_row(left, order, xs[j] - xs[left])
                                - derivative_row(right, order, 0.0))
                    rhs.append(0.0)
        a = np.array(rows)
        if a.shape[0] != a.shape[1]:
            raise NotImplementedError(
                "Spline: these points give a derivative at an interior point in a way whose "
                f"pieces this layer cannot place ({a.shape[0]} conditions for {a.shape[1]} "
                "coefficients); give both derivatives there, or neither")
        c = np.linalg.solve(a, np.array(rhs))
        return [c[start[i]:start[i + 1]] for i in range(n - 1)]

    def _piece_at(self, i: int, t: float, order: int) -> float:
        """Derivative ``order`` (0, 1, 2) of piece ``i`` at ``t`` (Horner's rule on plain
        floats: a nonlinear spring asks this on every evaluation)."""
        acc = 0.0
        for a in reversed(self._derived[order][i]):
            acc = acc * t + a
        return acc

    def _at(self, x: float, order: int) -> float:
        """Derivative ``order`` of the curve at ``x``: its piece's, or the end quadratic's."""
        xs = self._xs
        if x < xs[0] or x > xs[-1]:
            y, dy, ddy = self._ends[0] if x < xs[0] else self._ends[1]
            t = x - (xs[0] if x < xs[0] else xs[-1])
            return (y + dy * t + 0.5 * ddy * t * t, dy + ddy * t, ddy)[order]
        i = min(bisect.bisect_right(xs, x) - 1, len(xs) - 2)
        return self._piece_at(i, x - xs[i], order)

    def y(self, x: float) -> float:
        """The curve's value at ``x``."""
        return self._at(float(x), 0)

    def dy(self, x: float) -> float:
        """The curve's slope at ``x``."""
        return self._at(float(x), 1)

    def ddy(self, x: float) -> float:
        """The curve's second derivative at ``x``."""
        return self._at(float(x), 2)

    def _antiderivative(self, x: float) -> float:
        """``∫_{x₀}^x y``: the pieces' integrals, the end quadratics' beyond them."""
        xs = self._x

        def quadratic(values: np.ndarray, t: float) -> float:
            y, dy, ddy = values
            return y * t + dy * t * t / 2.0 + ddy * t ** 3 / 6.0

        def piece(i: int, t: float) -> float:
            c = self._pieces[i]
            powers = np.arange(1, len(c) + 1)
            return float(np.sum(c * t ** powers / powers))

        if x <= xs[0]:
            return quadratic(self._ends[0], x - xs[0])
        last = len(xs) - 2
        i = min(int(np.searchsorted(xs, x, side="right")) - 1, last)
        total = sum(piece(k, xs[k + 1] - xs[k]) for k in range(i))
        if x > xs[-1]:
            return total + piece(last, xs[-1] - xs[-2]) + quadratic(self._ends[1], x - xs[-1])
        return total + piece(i, x - xs[i])

    def integral(self, a: float, b: float) -> float:
        """``∫_a^b y(x) dx`` (exact; not in trep)."""
        return self._antiderivative(float(b)) - self._antiderivative(float(a))

    @property
    def x_points(self) -> np.ndarray:
        """The points' x (read-only)."""
        return self._x.copy()

    @property
    def y_points(self) -> np.ndarray:
        """The points' y (read-only)."""
        return self._y.copy()

    @property
    def coefficients(self) -> np.ndarray:
        """trep's table: a row of six coefficients (highest power first) for the quadratic
        before the points, for each piece (in ``t = x − x_i``) and for the quadratic after
        the points (in ``t = x − x_N``). trep writes the first in ``t = x − (x₀ − h)`` with
        ``h`` the *last* piece's width (its previous piece, counted from the end)."""
        xs = self._x
        rows = np.zeros((len(xs) + 1, 6))
        for i, c in enumerate(self._pieces):
            rows[i + 1, 6 - len(c):] = c[::-1]
        for row, (y, dy, ddy), shift in ((0, self._ends[0], -(xs[-1] - xs[-2])),
                                         (len(xs), self._ends[1], 0.0)):
            # The end's quadratic re-expanded about x_end + shift.
            rows[row, 3:] = [0.5 * ddy, dy + ddy * shift,
                             y + dy * shift + 0.5 * ddy * shift ** 2]
        return rows

    def copy(self) -> "Spline":
        """An independent copy."""
        new = object.__new__(Spline)
        new.__dict__.update({k: (v.copy() if isinstance(v, np.ndarray) else v)
                             for k, v in self.__dict__.items()})
        return new
