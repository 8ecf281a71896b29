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
from typing import Any, Dict, List, Optional, Tuple

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


def _symmetric_grid(configs: Any, rank: int, entry) -> List[float]:
    """:func:`_grid` of a derivative symmetric in its arguments (``V_dqdq``, ``h_dqdqdq``
    …): ``entry`` is called once per set of configs, arguments in config order (as trep
    calls a Hessian: once per pair), and the value copied to every permutation."""
    n = len(configs)
    if rank == 1:
        return [entry(a) for a in configs]
    out = [0.0] * n ** rank
    if rank == 2:
        for i, a in enumerate(configs):
            for j in range(i, n):
                out[i * n + j] = out[j * n + i] = entry(a, configs[j])
        return out
    for i, a in enumerate(configs):
        for j in range(i, n):
            b = configs[j]
            for k in range(j, n):
                v = entry(a, b, configs[k])
                for x, y, z in ((i, j, k), (i, k, j), (j, i, k), (j, k, i), (k, i, j),
                                (k, j, i)):
                    out[(x * n + y) * n + z] = v
    return out


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


class _Plan:
    """What every call back reads, found once per model: the configs (trep's order), the
    script's own parts, and their methods summed by name (:func:`_total`)."""

    def __init__(self, system: Any) -> None:
        self.configs = list(system._configs)
        self.n, self.nd = len(self.configs), system.nQd
        self.parts = ([p for p in system._potentials if defined_in_python(p)],
                      [f for f in system._forces if defined_in_python(f)],
                      [c for c in system._constraints if defined_in_python(c)])
        self._summed: Dict[Tuple[int, str], Any] = {}

    def _method(self, kind: int, name: str):
        method = self._summed.get((kind, name))
        if method is None:
            method = self._summed[(kind, name)] = _total(self.parts[kind], name)
        return method

    def potentials(self, name: str):
        """The potentials' method ``name``, summed."""
        return self._method(0, name)

    def forces(self, name: str):
        """The forces' method ``name``, summed."""
        return self._method(1, name)


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

    def plan(self) -> "_Plan":
        """What the calls back read every time, found once per model and kept on the
        system (which a structure change rebuilds with its model): on the native model's
        side, the parts' methods would hold the system through a cycle Python cannot see."""
        s = self.system
        plan = s._python_plan
        if plan is None:
            plan = s._python_plan = _Plan(s)
        return plan

    def parts(self) -> Tuple[List[Any], List[Any], List[Any]]:
        """The script's own potentials, forces and constraints."""
        return self.plan().parts

    def input_map(self, q: List[float], dq: List[float], u: np.ndarray, second: bool
                  ) -> Tuple[np.ndarray, Any, Any, Any]:
        """``B = ∂F/∂u`` for the inputs forces written in Python read (trep's dynamic configs
        × those inputs) at ``(q, q̇, u)`` (trep's order), and with ``second`` its derivatives
        ``∂B/∂q``, ``∂B/∂q̇`` (× every config) and ``∂²F/∂u∂u`` (× those inputs): each
        input's own force's ``f_du``, ``f_dudq``, ``f_duddq`` and ``f_dudu`` (another force's
        input is not its)."""
        s = self.system
        kept = (s._q, s._dq, s._u, s._cache)
        s._q, s._dq, s._u, s._cache = list(q), list(dq), np.asarray(u, dtype=float), {}
        s._in_callback = True
        try:
            dyn, configs, through = s.dyn_configs, s._configs, s._through
            shape = (len(dyn), len(through))
            b = np.array([[i.force.f_du(c, i) for i in through] for c in dyn]).reshape(shape)
            if not second:
                return b, None, None, None
            b_dq = np.array([[[i.force.f_dudq(c, i, a) for a in configs] for i in through]
                             for c in dyn]).reshape(shape + (len(configs),))
            b_dv = np.array([[[i.force.f_duddq(c, i, a) for a in configs] for i in through]
                             for c in dyn]).reshape(shape + (len(configs),))
            b_du = np.zeros(shape + (len(through),))
            for r, c in enumerate(dyn):
                for k, i in enumerate(through):
                    for m, j in enumerate(through):
                        if i.force is j.force:
                            b_du[r, k, m] = i.force.f_dudu(c, i, j)
            return b, b_dq, b_dv, b_du
        finally:
            s._q, s._dq, s._u, s._cache = kept
            s._in_callback = False

    def __call__(self, kind: str, order: int, q: List[float], dq: List[float],
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
            s._q, s._dq = q, dq
        else:
            s._q, s._dq = [q[i] for i in perm], [dq[i] for i in perm]
        s._cache, s._in_callback = {}, True
        try:
            if along is not None:
                along = (np.asarray(along[0])[perm], np.asarray(along[1])[perm])
            plan = s._python_plan or self.plan()
            if kind == "constraints":
                entries = _constraints(plan, s._dq, order, along)
            else:
                entries = _potentials(plan, kind == "lagrangian", order, along)
                if kind == "terms":
                    entries += _forces(plan, order, along)
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


def _potentials(plan: "_Plan", energy_only: bool, order: int, along) -> list:
    """``L = −ΣV`` and its derivatives (trep's ``V``, ``V_dq``, ``V_dqdq``, ``V_dqdqdq``)."""
    configs, n, method = plan.configs, plan.n, plan.potentials
    lagrangian = -method("V")()
    if energy_only and along is None:
        return [("L", [lagrangian], None)]
    v_dq = method("V_dq")
    dl = [-v_dq(a) for a in configs]
    if along is None and order != ORDER_FULL:
        return [("L", [lagrangian], None), ("dL_dq", dl, None)]
    dq_along = along[0] if along is not None else None
    if energy_only:
        return [("L", [lagrangian], [float(np.dot(dl, dq_along))])]
    v_dqdq = method("V_dqdq")
    d2l = _symmetric_grid(configs, 2, lambda a, b: -v_dqdq(a, b))
    if along is None:
        return [("L", [lagrangian], None), ("dL_dq", dl, None), ("d2L_dqdq", d2l, None)]
    out = [("L", [lagrangian], [float(np.dot(dl, dq_along))]),
           ("dL_dq", dl, _array(d2l, n, 2) @ dq_along)]
    if order == ORDER_FULL:
        v_dqdqdq = method("V_dqdqdq")
        d3l = _symmetric_grid(configs, 3, lambda a, b, c: -v_dqdqdq(a, b, c))
        out.append(("d2L_dqdq", d2l, _array(d3l, n, 3) @ dq_along))
    return out

def _forces(plan: "_Plan", order: int, along) -> list:
    """``F`` on the dynamic configs and its derivatives (trep's ``f``, ``f_dq``,
    ``f_ddq``, and for a direction ``f_dqdq``, ``f_ddqdq``, ``f_ddqddq``); zero on the
    kinematic ones."""
    if not plan.parts[1]:
        return []
    configs, n, nd = plan.configs, plan.n, plan.nd

    def each(name: str, rank: int) -> List[float]:
        """The forces' ``name`` method summed, rows on the dynamic configs only."""
        zeros = [0.0] * ((n - nd) * n ** (rank - 1))
        method = plan.forces(name)
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

def _constraints(plan: "_Plan", dq_now: List[float], order: int, along) -> list:
    """The script's constraint rows (trep's ``h``, ``h_dq``, ``h_dqdq``, ``h_dqdqdq``)."""
    rows = plan.parts[2]
    configs, n, m = plan.configs, plan.n, len(rows)

    def each(name: str, rank: int) -> List[float]:
        return [x for c in rows for x in _symmetric_grid(configs, rank, getattr(c, name))]

    h, dh = [c.h() for c in rows], each("h_dq", 1)
    if along is None and order < ORDER_DYNAMICS:
        return [("h", h, None), ("Dh", dh, None)]
    d2h = np.asarray(each("h_dqdq", 2), dtype=float).reshape(m, n, n)
    dq = np.array(dq_now)
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
