//! A scalar that records instead of computing. Running the runtime's recursions over it
//! yields the straight-line program for one fixed tree: constants fold as they meet
//! (`Const ⊕ Const` is computed now), structural zeros vanish (`0·x`, `0 + x`), and only
//! what depends on `q`, `q̇` becomes a statement. The folds are exact in IEEE arithmetic for
//! finite values, so the program computes the same numbers as the interpreted runtime. A
//! statement recorded twice (the same operation on the same operands) is kept once.

use std::cell::RefCell;
use std::collections::HashMap;
use std::fmt;
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

use tree_kernel::Scalar;

/// A traced value: a constant known now, or the result of statement `n` of the tape.
#[derive(Clone, Copy, PartialEq)]
pub enum Term {
    Const(f64),
    Var(u32),
}

impl fmt::Debug for Term {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Term::Const(c) => write!(f, "{c:?}"),
            Term::Var(v) => write!(f, "t{v}"),
        }
    }
}

/// One recorded statement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Node {
    Q(usize),
    Dq(usize),
    /// The generalized force on variable i (the articulated-body step's input `out.tau[i]`).
    Tau(usize),
    /// A kinematic variable's prescribed acceleration (`out.qdd_in[i]`).
    KinematicQdd(usize),
    /// The acceleration an inverse-dynamics evaluation is asked for (`out.acceleration(i)`).
    Qdd(usize),
    /// Constraint row r's weight in a weighted Hessian (`out.weights[r]`).
    Weight(usize),
    Add(Term, Term),
    Sub(Term, Term),
    Mul(Term, Term),
    Neg(Term),
    Sin(Term),
    Cos(Term),
    Sqrt(Term),
    Recip(Term),
}

/// The statements recorded so far, and each one's index for reuse: a statement that was
/// already recorded (commutative operands in either order) is not recorded again.
#[derive(Default)]
struct Tape {
    nodes: Vec<Node>,
    seen: HashMap<NodeKey, u32>,
}

/// An operand by kind and bit pattern: hashable, and equal exactly when the operands are.
type OperandKey = (bool, u64);

/// A node with commutative operands ordered.
type NodeKey = (u8, OperandKey, OperandKey);

fn key(node: &Node) -> NodeKey {
    let bits = |t: Term| match t {
        Term::Const(c) => (false, c.to_bits()),
        Term::Var(v) => (true, v as u64),
    };
    let none = (false, 0);
    let ordered = |a: Term, b: Term| {
        let (x, y) = (bits(a), bits(b));
        (x.min(y), x.max(y))
    };
    match *node {
        Node::Q(i) => (0, (false, i as u64), none),
        Node::Dq(i) => (1, (false, i as u64), none),
        Node::Tau(i) => (10, (false, i as u64), none),
        Node::KinematicQdd(i) => (11, (false, i as u64), none),
        Node::Qdd(i) => (12, (false, i as u64), none),
        Node::Weight(r) => (13, (false, r as u64), none),
        Node::Add(a, b) => {
            let (x, y) = ordered(a, b);
            (2, x, y)
        }
        Node::Sub(a, b) => (3, bits(a), bits(b)),
        Node::Mul(a, b) => {
            let (x, y) = ordered(a, b);
            (4, x, y)
        }
        Node::Neg(a) => (5, bits(a), none),
        Node::Sin(a) => (6, bits(a), none),
        Node::Cos(a) => (7, bits(a), none),
        Node::Sqrt(a) => (8, bits(a), none),
        Node::Recip(a) => (9, bits(a), none),
    }
}

thread_local! {
    static TAPE: RefCell<Tape> = RefCell::new(Tape::default());
}

fn push(node: Node) -> Term {
    TAPE.with(|t| {
        let mut t = t.borrow_mut();
        let k = key(&node);
        if let Some(&v) = t.seen.get(&k) {
            return Term::Var(v);
        }
        let v = t.nodes.len() as u32;
        t.nodes.push(node);
        t.seen.insert(k, v);
        Term::Var(v)
    })
}

/// Runs `f` on a fresh tape and returns what it recorded with its result.
pub fn record<R>(f: impl FnOnce() -> R) -> (Vec<Node>, R) {
    TAPE.with(|t| *t.borrow_mut() = Tape::default());
    let r = f();
    let nodes = TAPE.with(|t| std::mem::take(&mut t.borrow_mut().nodes));
    (nodes, r)
}

/// The input `q[i]`.
pub fn q(i: usize) -> Term {
    push(Node::Q(i))
}

/// The input `q̇[i]`.
pub fn dq(i: usize) -> Term {
    push(Node::Dq(i))
}

/// The input `τ[i]`, the generalized force on variable i.
pub fn tau(i: usize) -> Term {
    push(Node::Tau(i))
}

/// The input `q̈[i]` an inverse-dynamics evaluation is asked for.
pub fn qdd(i: usize) -> Term {
    push(Node::Qdd(i))
}

/// The input `w[r]`, constraint row r's weight.
pub fn weight(r: usize) -> Term {
    push(Node::Weight(r))
}

/// The input `q̈[i]` of a kinematic variable (its prescription).
pub fn kinematic_qdd(i: usize) -> Term {
    push(Node::KinematicQdd(i))
}

impl Add for Term {
    type Output = Term;
    fn add(self, rhs: Term) -> Term {
        match (self, rhs) {
            (Term::Const(a), Term::Const(b)) => Term::Const(a + b),
            (Term::Const(z), x) | (x, Term::Const(z)) if z == 0.0 => x,
            (a, b) => push(Node::Add(a, b)),
        }
    }
}

impl Sub for Term {
    type Output = Term;
    fn sub(self, rhs: Term) -> Term {
        match (self, rhs) {
            (Term::Const(a), Term::Const(b)) => Term::Const(a - b),
            (x, Term::Const(0.0)) => x,
            (Term::Const(0.0), x) => -x,
            (a, b) => push(Node::Sub(a, b)),
        }
    }
}

impl Mul for Term {
    type Output = Term;
    fn mul(self, rhs: Term) -> Term {
        match (self, rhs) {
            (Term::Const(a), Term::Const(b)) => Term::Const(a * b),
            (Term::Const(z), _) | (_, Term::Const(z)) if z == 0.0 => Term::Const(0.0),
            (Term::Const(o), x) | (x, Term::Const(o)) if o == 1.0 => x,
            (Term::Const(m), x) | (x, Term::Const(m)) if m == -1.0 => -x,
            (a, b) => push(Node::Mul(a, b)),
        }
    }
}

impl Neg for Term {
    type Output = Term;
    fn neg(self) -> Term {
        match self {
            Term::Const(a) => Term::Const(-a),
            x => push(Node::Neg(x)),
        }
    }
}

impl AddAssign for Term {
    fn add_assign(&mut self, rhs: Term) {
        *self = *self + rhs;
    }
}

impl SubAssign for Term {
    fn sub_assign(&mut self, rhs: Term) {
        *self = *self - rhs;
    }
}

impl Scalar for Term {
    fn constant(x: f64) -> Self {
        Term::Const(x)
    }

    fn sin_cos(self) -> (Self, Self) {
        match self {
            Term::Const(a) => (Term::Const(a.sin()), Term::Const(a.cos())),
            x => (push(Node::Sin(x)), push(Node::Cos(x))),
        }
    }

    fn sqrt(self) -> Self {
        match self {
            Term::Const(a) => Term::Const(a.sqrt()),
            x => push(Node::Sqrt(x)),
        }
    }

    fn recip(self) -> Self {
        match self {
            Term::Const(a) => Term::Const(1.0 / a),
            x => push(Node::Recip(x)),
        }
    }
}
