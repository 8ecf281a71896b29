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
    """Whether a potential, force or constraint is a script's own subclass (not one of the
    layer's built-in elements, which become model text)."""
    return not type(part).__module__.startswith("tree_mech.")


def _tensor(n: int, rank: int, entry) -> np.ndarray:
    """The n × … × n array of ``entry(i, j, …)``."""
    r = range(n)
    if rank == 1:
        return np.array([entry(i) for i in r], dtype=float)
    if rank == 2:
        return np.array([[entry(i, j) for j in r] for i in r], dtype=float).reshape(n, n)
    return np.array([[[entry(i, j, k) for k in r] for j in r] for i in r],
                    dtype=float).reshape(n, n, n)


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
        kept = (s._q.copy(), s._dq.copy())
        if self.identity:
            s._q[:], s._dq[:] = q, dq
        else:
            s._q[:], s._dq[:] = np.asarray(q)[perm], np.asarray(dq)[perm]
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
            s._q[:], s._dq[:] = kept
        if self.identity and along is None:  # the stepping path's lists, as they are
            return [e if isinstance(e[1], list) and not (e[1] and isinstance(e[1][0], list))
                    else self._model_order(*e) for e in entries]
        return [self._model_order(key, value, tangent) for key, value, tangent in entries]

    def _model_order(self, key: str, value: np.ndarray, tangent: Optional[np.ndarray]):
        """An output's entries moved from trep's config order to the model's, flattened."""
        perm = self.system._perm

        def move(x: Any) -> list:
            if isinstance(x, list) and self.identity and not (x and isinstance(x[0], list)):
                return x  # flat already, and in the model's order
            x = np.asarray(x, dtype=float)
            if self.identity or key in ("L", "h", "dh_dot"):
                return x.ravel().tolist()
            out = np.zeros_like(x)
            if key in ("Dh", "D2h"):  # rows stay; config axes move
                out[(slice(None),) + tuple(np.ix_(*[perm] * (x.ndim - 1)))] = x
            else:
                out[np.ix_(*[perm] * x.ndim)] = x
            return out.ravel().tolist()

        return (key, move(value), None if tangent is None else move(tangent))

    def _potentials(self, energy_only: bool, order: int, along) -> list:
        """``L = −ΣV`` and its derivatives (trep's ``V``, ``V_dq``, ``V_dqdq``, ``V_dqdqdq``)."""
        potentials = self.parts()[0]
        configs = self.system._configs
        n = len(configs)
        v = sum(p.V() for p in potentials)
        if energy_only and along is None:
            return [("L", [-v], None)]
        if along is None:  # plain lists: the stepping path
            out = [("L", [-v], None),
                   ("dL_dq", [-sum(p.V_dq(c) for p in potentials) for c in configs], None)]
            if order == ORDER_FULL:
                out.append(("d2L_dqdq", [-sum(p.V_dqdq(a, b) for p in potentials)
                                         for a in configs for b in configs], None))
            return out
        dv = _tensor(n, 1, lambda i: sum(p.V_dq(configs[i]) for p in potentials))
        if energy_only:
            return [("L", -np.float64(v), -np.float64(dv @ along[0]))]
        full = order == ORDER_FULL
        second = full or along is not None
        d2v = (_tensor(n, 2, lambda i, j: sum(p.V_dqdq(configs[i], configs[j])
                                              for p in potentials)) if second else None)
        out = [("L", -np.float64(v), None if along is None else -np.float64(dv @ along[0])),
               ("dL_dq", -dv, None if along is None else -(d2v @ along[0]))]
        if full:
            tangent = None
            if along is not None:
                d3v = _tensor(n, 3, lambda i, j, k: sum(
                    p.V_dqdqdq(configs[i], configs[j], configs[k]) for p in potentials))
                tangent = -(d3v @ along[0])
            out.append(("d2L_dqdq", -d2v, tangent))
        return out

    def _forces(self, order: int, along) -> list:
        """``F`` on the dynamic configs and its derivatives (trep's ``f``, ``f_dq``,
        ``f_ddq``, and for a direction ``f_dqdq``, ``f_ddqdq``, ``f_ddqddq``)."""
        forces = self.parts()[1]
        if not forces:
            return []
        s = self.system
        configs, n, nd = s._configs, len(s._configs), s.nQd

        def on(i: int, call) -> float:
            return sum(call(f) for f in forces) if i < nd else 0.0

        full = order == ORDER_FULL
        if along is None:  # plain lists: the stepping path
            dynamic = configs[:nd]
            rows = [0.0] * (n - nd)
            out = [("F", [sum(x.f(a) for x in forces) for a in dynamic] + rows, None)]
            if full:
                zeros = [0.0] * (n * (n - nd))
                out += [(key, [sum(getattr(x, name)(a, b) for x in forces)
                               for a in dynamic for b in configs] + zeros, None)
                        for key, name in (("dF_dq", "f_dq"), ("dF_ddq", "f_ddq"))]
            return out
        f = _tensor(n, 1, lambda i: on(i, lambda x: x.f(configs[i])))
        first = full or along is not None
        if first:
            f_dq = _tensor(n, 2, lambda i, j: on(i, lambda x: x.f_dq(configs[i], configs[j])))
            f_ddq = _tensor(n, 2, lambda i, j: on(i, lambda x: x.f_ddq(configs[i], configs[j])))
        out = [("F", f, None if along is None else f_dq @ along[0] + f_ddq @ along[1])]
        if full:
            t_dq = t_ddq = None
            if along is not None:
                c = configs
                qq = _tensor(n, 3, lambda i, j, k: on(i, lambda x: x.f_dqdq(c[i], c[j], c[k])))
                vq = _tensor(n, 3, lambda i, j, k: on(i, lambda x: x.f_ddqdq(c[i], c[j], c[k])))
                vv = _tensor(n, 3, lambda i, j, k: on(i, lambda x: x.f_ddqddq(c[i], c[j], c[k])))
                # vq[i, j, k] = ∂²F_i/∂q̇_j∂q_k.
                t_dq = qq @ along[0] + np.einsum("ikj,k->ij", vq, along[1])
                t_ddq = vq @ along[0] + vv @ along[1]
            out += [("dF_dq", f_dq, t_dq), ("dF_ddq", f_ddq, t_ddq)]
        return out

    def _constraints(self, order: int, along) -> list:
        """The script's constraint rows (trep's ``h``, ``h_dq``, ``h_dqdq``, ``h_dqdqdq``)."""
        rows = self.parts()[2]
        s = self.system
        configs, n = s._configs, len(s._configs)
        if along is None and order < ORDER_DYNAMICS:
            return [("h", [c.h() for c in rows], None),
                    ("Dh", [[c.h_dq(a) for a in configs] for c in rows], None)]
        dq = s._dq.copy()
        h = np.array([c.h() for c in rows], dtype=float)
        dh = np.array([_tensor(n, 1, lambda i: c.h_dq(configs[i])) for c in rows]).reshape(
            len(rows), n)
        second = order >= ORDER_DYNAMICS or along is not None
        d2h = (np.array([_tensor(n, 2, lambda i, j: c.h_dqdq(configs[i], configs[j]))
                         for c in rows]).reshape(len(rows), n, n) if second else None)
        d3h = None
        if along is not None and order >= ORDER_DYNAMICS:
            d3h = np.array([_tensor(n, 3, lambda i, j, k: c.h_dqdqdq(
                configs[i], configs[j], configs[k])) for c in rows]).reshape(len(rows), n, n, n)
        out = [("h", h, None if along is None else dh @ along[0]),
               ("Dh", dh, None if along is None else d2h @ along[0])]
        if order >= ORDER_DYNAMICS:
            dot = np.einsum("rij,i,j->r", d2h, dq, dq)
            tangent = None
            if along is not None:
                tangent = (np.einsum("rijk,i,j,k->r", d3h, dq, dq, along[0])
                           + 2.0 * np.einsum("rij,i,j->r", d2h, dq, along[1]))
            out.append(("dh_dot", dot, tangent))
        if order == ORDER_FULL:
            out.append(("D2h", d2h, None if along is None else d3h @ along[0]))
        return out
