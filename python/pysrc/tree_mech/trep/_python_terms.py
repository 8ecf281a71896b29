"""Potentials, forces and constraints a script writes in Python (subclasses of trep's
``Potential``, ``Force`` and ``Constraint`` with their own ``V``/``f``/``h`` and derivatives),
evaluated for the Rust runtime, which asks for them on every evaluation, step and derivative
(``Model.add_python_terms``): the system is put at the asked state, the elements' methods
are called as trep calls them, one config at a time, and the state is put back.

What each ask needs, as trep needs it (a derivative a script does not write raises trep's
``NotImplementedError`` when it is needed, and nothing is approximated):

* the Lagrangian's terms (``L = −ΣV``, ``∂L/∂q``; at the full order ``∂²L/∂q²``) and the
  forces ``F`` on the dynamic configs (at the full order ``∂F/∂q``, ``∂F/∂q̇``);
* the constraint rows ``h``, ``∂h/∂q`` (``q̇ᵀ∂²h/∂q²q̇`` for the dynamics; ``∂²h/∂q²`` at the
  full order), after the built-in ones;
* along a direction ``(δq, δq̇)``, each output's derivative: one more derivative of each
  (``V_dqdqdq``, ``f_dqdq``, ``f_ddqdq``, ``f_ddqddq``, ``h_dqdqdq`` for the step's second
  derivatives).
"""
from __future__ import annotations

import weakref
from typing import Any, List, Optional, Tuple

import numpy as np

ORDER_DYNAMICS, ORDER_FULL = 1, 2


def defined_in_python(part: Any) -> bool:
    """Whether a potential, force or constraint is called back: a script's own subclass, or
    one of the layer's elements that is no model text (``_called_back``: the wrenches, the
    nonlinear spring)."""
    return (getattr(part, "_called_back", False)
            or not type(part).__module__.startswith("tree_mech."))


def _grid(configs: Any, rank: int, entry) -> List[float]:
    """``entry(a, b, …)`` over every ``rank``-tuple of configs, flattened row-major (the
    values a callback hands back, in trep's order)."""
    if rank == 1:
        return [entry(a) for a in configs]
    if rank == 2:
        return [entry(a, b) for a in configs for b in configs]
    return [entry(a, b, c) for a in configs for b in configs for c in configs]


def _total(parts: List[Any], name: str):
    """The parts' method ``name`` summed, as one callable (the method itself for one part:
    this runs several times a step)."""
    methods = [getattr(p, name) for p in parts]
    if len(methods) == 1:
        return methods[0]
    return lambda *args: sum(m(*args) for m in methods)


def _array(values: List[float], n: int, rank: int) -> np.ndarray:
    """Flat values as an n × … × n array (for the derivatives along a direction)."""
    return np.asarray(values, dtype=float).reshape((n,) * rank)


class PythonTerms:
    """The callable ``Model.add_python_terms`` is given for ``system``. A failure in a
    script's method is kept in ``error`` (the first one) and hands ``None``, which the
    runtime turns into NaN and refuses; the system then raises the kept error itself."""

    def __init__(self, system: Any) -> None:
        # Held weakly: the system holds its native model, which holds this (a strong
        # reference back would be a cycle through Rust that Python's collector cannot see).
        self._system = weakref.ref(system)
        self.error: Optional[BaseException] = None
        perm = system._perm
        #: Whether trep's config order is the model's (then nothing is moved).
        self.identity = bool(np.all(perm == np.arange(len(perm))))

    @property
    def system(self) -> Any:
        """The system whose elements these are."""
        return self._system()

    def parts(self) -> Tuple[List[Any], List[Any], List[Any]]:
        """The script's own potentials, forces and constraints (kept on the system, which a
        structure change rebuilds with its model)."""
        s = self.system
        parts = getattr(s, "_python_parts", None)
        if parts is None:
            parts = ([p for p in s._potentials if defined_in_python(p)],
                     [f for f in s._forces if defined_in_python(f)],
                     [c for c in s._constraints if defined_in_python(c)])
            s._python_parts = parts
        return parts

    def __call__(self, kind: str, order: int, q: np.ndarray, dq: np.ndarray,
                 along: Optional[Tuple[np.ndarray, np.ndarray]]) -> Optional[list]:
        try:
            return self._at(kind, order, q, dq, along)
        except BaseException as e:  # kept, and raised by the system after the native call
            if self.error is None:
                self.error = e
            return None

    def _at(self, kind, order, q, dq, along) -> list:
        """Puts the system at ``(q, q̇)`` (model order), evaluates, and puts it back."""
        s = self.system
        perm = s._perm
        kept = (s._q, s._dq, s._cache)
        # The state as plain lists while the script's methods read it (a list is read
        # several times faster than an array); a frame read now is evaluated at this state,
        # on the model without these elements.
        if self.identity:
            s._q, s._dq = q.tolist(), dq.tolist()
        else:
            s._q, s._dq = np.asarray(q)[perm].tolist(), np.asarray(dq)[perm].tolist()
        s._cache, s._in_callback = {}, True
        try:
            if along is not None:
                along = (np.asarray(along[0])[perm], np.asarray(along[1])[perm])
            if kind == "constraints":
                entries = self._constraints(order, along)
            else:
                entries = self._potentials(kind == "lagrangian", order, along)
                if kind == "terms":
                    entries += self._forces(order, along)
        finally:
            s._q, s._dq, s._cache = kept
            s._in_callback = False
        return [(key, self._model_order(key, value),
                 None if tangent is None else self._model_order(key, tangent))
                for key, value, tangent in entries]

    #: Each output's config axes (moved into the model's order), after its constraint row
    #: axis if it has one.
    _CONFIG_AXES = {"L": 0, "dL_dq": 1, "F": 1, "d2L_dqdq": 2, "dF_dq": 2, "dF_ddq": 2,
                    "h": 0, "dh_dot": 0, "Dh": 1, "D2h": 2}

    def _model_order(self, key: str, x: Any) -> List[float]:
        """An output's entries (flat values or an array of derivatives, trep's config order)
        in the model's order, flattened."""
        axes = self._CONFIG_AXES[key]
        if self.identity or axes == 0:
            return x if isinstance(x, list) else np.ravel(x).tolist()
        perm = self.system._perm
        x = np.asarray(x, dtype=float).reshape((-1,) + (len(perm),) * axes)
        out = np.zeros_like(x)
        out[(slice(None),) + np.ix_(*[perm] * axes)] = x
        return out.ravel().tolist()

    def _potentials(self, energy_only: bool, order: int, along) -> list:
        """``L = −ΣV`` and its derivatives (trep's ``V``, ``V_dq``, ``V_dqdq``, ``V_dqdqdq``)."""
        ps = self.parts()[0]
        configs = self.system._configs
        n = len(configs)
        lagrangian = -_total(ps, "V")()
        if energy_only and along is None:
            return [("L", [lagrangian], None)]
        v_dq = _total(ps, "V_dq")
        dl = [-v_dq(a) for a in configs]
        if along is None and order != ORDER_FULL:
            return [("L", [lagrangian], None), ("dL_dq", dl, None)]
        dq_along = along[0] if along is not None else None
        if energy_only:
            return [("L", [lagrangian], [float(np.dot(dl, dq_along))])]
        v_dqdq = _total(ps, "V_dqdq")
        d2l = [-v_dqdq(a, b) for a in configs for b in configs]
        if along is None:
            return [("L", [lagrangian], None), ("dL_dq", dl, None), ("d2L_dqdq", d2l, None)]
        out = [("L", [lagrangian], [float(np.dot(dl, dq_along))]),
               ("dL_dq", dl, _array(d2l, n, 2) @ dq_along)]
        if order == ORDER_FULL:
            v_dqdqdq = _total(ps, "V_dqdqdq")
            d3l = _grid(configs, 3, lambda a, b, c: -v_dqdqdq(a, b, c))
            out.append(("d2L_dqdq", d2l, _array(d3l, n, 3) @ dq_along))
        return out

    def _forces(self, order: int, along) -> list:
        """``F`` on the dynamic configs and its derivatives (trep's ``f``, ``f_dq``,
        ``f_ddq``, and for a direction ``f_dqdq``, ``f_ddqdq``, ``f_ddqddq``); zero on the
        kinematic ones."""
        fs = self.parts()[1]
        if not fs:
            return []
        s = self.system
        configs, n, nd = s._configs, len(s._configs), s.nQd

        def each(name: str, rank: int) -> List[float]:
            """The forces' ``name`` method summed, rows on the dynamic configs only."""
            zeros = [0.0] * ((n - nd) * n ** (rank - 1))
            method = _total(fs, name)
            if rank == 1:
                return [method(a) for a in configs[:nd]] + zeros
            if rank == 2:
                return [method(a, b) for a in configs[:nd] for b in configs] + zeros
            rest = _grid(configs, rank - 1, lambda *b: b)
            return [method(a, *b) for a in configs[:nd] for b in rest] + zeros

        f = each("f", 1)
        full = order == ORDER_FULL
        if along is None and not full:
            return [("F", f, None)]
        f_dq, f_ddq = each("f_dq", 2), each("f_ddq", 2)
        if along is None:
            return [("F", f, None), ("dF_dq", f_dq, None), ("dF_ddq", f_ddq, None)]
        dq_along, ddq_along = along
        m_dq, m_ddq = _array(f_dq, n, 2), _array(f_ddq, n, 2)
        out = [("F", f, m_dq @ dq_along + m_ddq @ ddq_along)]
        if full:
            qq = _array(each("f_dqdq", 3), n, 3)
            vq = _array(each("f_ddqdq", 3), n, 3)  # vq[i, j, k] = ∂²F_i/∂q̇_j∂q_k
            vv = _array(each("f_ddqddq", 3), n, 3)
            out += [("dF_dq", f_dq, qq @ dq_along + np.einsum("ikj,k->ij", vq, ddq_along)),
                    ("dF_ddq", f_ddq, vq @ dq_along + vv @ ddq_along)]
        return out

    def _constraints(self, order: int, along) -> list:
        """The script's constraint rows (trep's ``h``, ``h_dq``, ``h_dqdq``, ``h_dqdqdq``)."""
        rows = self.parts()[2]
        s = self.system
        configs, n, m = s._configs, len(s._configs), len(rows)

        def each(name: str, rank: int) -> List[float]:
            return [x for c in rows for x in _grid(configs, rank, getattr(c, name))]

        h, dh = [c.h() for c in rows], each("h_dq", 1)
        if along is None and order < ORDER_DYNAMICS:
            return [("h", h, None), ("Dh", dh, None)]
        d2h = np.asarray(each("h_dqdq", 2), dtype=float).reshape(m, n, n)
        dq = np.array(s._dq)
        out = [("h", h, None if along is None else np.asarray(dh).reshape(m, n) @ along[0]),
               ("Dh", dh, None if along is None else d2h @ along[0])]
        d3h = None
        if along is not None and order >= ORDER_DYNAMICS:
            d3h = np.asarray(each("h_dqdqdq", 3), dtype=float).reshape(m, n, n, n)
        if order >= ORDER_DYNAMICS:
            tangent = None
            if along is not None:
                tangent = (np.einsum("rijk,i,j,k->r", d3h, dq, dq, along[0])
                           + 2.0 * np.einsum("rij,i,j->r", d2h, dq, along[1]))
            out.append(("dh_dot", np.einsum("rij,i,j->r", d2h, dq, dq), tangent))
        if order == ORDER_FULL:
            out.append(("D2h", d2h, None if along is None else d3h @ along[0]))
        return out
