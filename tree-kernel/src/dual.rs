//! Forward-mode dual numbers `v + d·ε` (ε² = 0): the kernel evaluated over them gives, beside
//! every output, its exact derivative along one direction of `(q, q̇)` — how the continuous
//! linearisation differentiates `M`, `∂L/∂q`, `Dh`, … without finite differences.

use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

use crate::order::Order;
use crate::outputs::{clear_among, Field, Index, Output, Scratch, Sink};
use crate::scalar::Scalar;

/// `v + d·ε`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dual {
    /// The value.
    pub v: f64,
    /// Its derivative along the chosen direction.
    pub d: f64,
}

impl Dual {
    /// `v + d·ε`.
    pub fn new(v: f64, d: f64) -> Self {
        Dual { v, d }
    }

    /// `x + δx·ε`, entry by entry: a point seeded with a direction.
    pub fn seed(x: &[f64], dx: &[f64]) -> Vec<Dual> {
        x.iter().zip(dx).map(|(&v, &d)| Dual::new(v, d)).collect()
    }
}

impl Add for Dual {
    type Output = Dual;
    #[inline(always)]
    fn add(self, o: Dual) -> Dual {
        Dual::new(self.v + o.v, self.d + o.d)
    }
}

impl Sub for Dual {
    type Output = Dual;
    #[inline(always)]
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self.v - o.v, self.d - o.d)
    }
}

impl Mul for Dual {
    type Output = Dual;
    #[inline(always)]
    fn mul(self, o: Dual) -> Dual {
        Dual::new(self.v * o.v, self.d * o.v + self.v * o.d)
    }
}

impl Neg for Dual {
    type Output = Dual;
    #[inline(always)]
    fn neg(self) -> Dual {
        Dual::new(-self.v, -self.d)
    }
}

impl AddAssign for Dual {
    #[inline(always)]
    fn add_assign(&mut self, o: Dual) {
        *self = *self + o;
    }
}

impl SubAssign for Dual {
    #[inline(always)]
    fn sub_assign(&mut self, o: Dual) {
        *self = *self - o;
    }
}

impl Scalar for Dual {
    #[inline(always)]
    fn constant(x: f64) -> Self {
        Dual::new(x, 0.0)
    }

    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.v.sin_cos();
        (Dual::new(s, c * self.d), Dual::new(c, -s * self.d))
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        let r = self.v.sqrt();
        Dual::new(r, 0.5 * self.d / r)
    }

    #[inline(always)]
    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        Dual::new(r, -self.d * r * r)
    }
}

/// Every output of one dual evaluation, by field (the one table, [`Output::slot`]): for `n`
/// variables and `m` constraint rows, vectors and matrices dense, row-major.
#[derive(Clone, Debug)]
pub struct DualOutputs {
    n: usize,
    /// One buffer per [`Field`], in its declaration order.
    fields: Vec<Vec<Dual>>,
    /// Each constraint row's variables, where known
    /// ([`Self::with_constraint_variables`]): its `D²h` block is cleared on them alone.
    variables: Vec<Vec<usize>>,
    /// The weights of [`Field::WeightedD2h`] (`System::weighted_constraint_hessian_dual`'s
    /// input, which generated code reads through [`Sink::weight`]).
    weights: Vec<Dual>,
    /// Generated code's storage between its functions (not part of the outputs).
    #[doc(hidden)]
    pub scratch: Scratch<Dual>,
}

/// Every field, in declaration order (so `field as usize` indexes it).
const FIELDS: [Field; 16] = [
    Field::L,
    Field::Energy,
    Field::DlDq,
    Field::DlDdq,
    Field::Mass,
    Field::D2lDdqDq,
    Field::D2lDqDq,
    Field::Force,
    Field::DforceDq,
    Field::DforceDdq,
    Field::H,
    Field::Dh,
    Field::DhDot,
    Field::D2h,
    Field::WeightedD2h,
    Field::Tau,
];

impl DualOutputs {
    /// Zeros for `n` variables and `m` constraint rows.
    pub fn new(n: usize, m: usize) -> Self {
        let size = |f: Field| match f {
            Field::L | Field::Energy => 1,
            Field::DlDq | Field::DlDdq | Field::Force | Field::Tau => n,
            Field::Mass | Field::D2lDdqDq | Field::D2lDqDq | Field::DforceDq | Field::DforceDdq => {
                n * n
            }
            Field::H | Field::DhDot => m,
            Field::Dh => m * n,
            Field::D2h => m * n * n,
            Field::WeightedD2h => n * n,
        };
        DualOutputs {
            n,
            fields: FIELDS
                .iter()
                .map(|&f| vec![Dual::default(); size(f)])
                .collect(),
            variables: Vec::new(),
            weights: Vec::new(),
            scratch: Scratch::default(),
        }
    }

    /// Ready for a weighted Hessian over dual numbers
    /// (`System::weighted_constraint_hessian_dual`): `weights` kept as its input, `h`, `Dh`
    /// and [`Field::WeightedD2h`] zeroed (the evaluation accumulates into them). Panics
    /// unless there is one weight per constraint row (a caller's error, not input's).
    pub fn weigh(&mut self, weights: &[Dual]) {
        let rows = self.fields[Field::H as usize].len();
        assert_eq!(weights.len(), rows, "one weight per constraint row");
        self.weights.clear();
        self.weights.extend_from_slice(weights);
        for f in [Field::H, Field::Dh, Field::WeightedD2h] {
            self.fields[f as usize].fill(Dual::default());
        }
    }

    /// These outputs with constraint row r's `D²h` block known to lie on `variables[r]`
    /// (as a system names them, `System::constraint_variables`): clearing `D²h` zeroes
    /// each row's block on them alone, as `ConstraintTerms::of` does (an evaluation never
    /// writes outside those blocks, so entries there stay zero). Empty: not known.
    pub fn with_constraint_variables(mut self, variables: Vec<Vec<usize>>) -> Self {
        self.variables = variables;
        self
    }

    /// Zeroes every output.
    pub fn clear(&mut self) {
        for f in &mut self.fields {
            f.fill(Dual::default());
        }
    }

    /// Zeroes the Lagrangian's and the forces' outputs an evaluation of `order` accumulates
    /// (as `Terms::clear`); the constraints' are left as they are.
    pub fn clear_lagrangian(&mut self, order: Order) {
        let first = [
            Field::L,
            Field::Energy,
            Field::DlDq,
            Field::DlDdq,
            Field::Force,
        ];
        let dynamics = [Field::Mass, Field::D2lDdqDq];
        let full = [Field::D2lDqDq, Field::DforceDq, Field::DforceDdq];
        let fields = first
            .iter()
            .chain(dynamics.iter().filter(|_| order >= Order::Dynamics))
            .chain(full.iter().filter(|_| order >= Order::Full));
        for &f in fields {
            self.fields[f as usize].fill(Dual::default());
        }
    }

    /// Zeroes the constraints' outputs an evaluation of `order` accumulates: `h`, `Dh`, from
    /// `Order::Dynamics` on `q̇ᵀD²h q̇`, at `Order::Full` `D²h` (each row's block on its
    /// variables alone where they are known, [`Self::with_constraint_variables`]).
    pub fn clear_constraints(&mut self, order: Order) {
        self.fields[Field::H as usize].fill(Dual::default());
        self.fields[Field::Dh as usize].fill(Dual::default());
        if order >= Order::Dynamics {
            self.fields[Field::DhDot as usize].fill(Dual::default());
        }
        if order < Order::Full {
            return;
        }
        let n = self.n;
        let d2h = &mut self.fields[Field::D2h as usize];
        if self.variables.is_empty() {
            d2h.fill(Dual::default());
        }
        for (block, vars) in d2h.chunks_exact_mut(n * n).zip(&self.variables) {
            clear_among(block, n, vars, Dual::default());
        }
    }

    /// Number of variables.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Every entry of `field`, dense and row-major (`D2h` row after row).
    #[inline]
    pub fn field(&self, field: Field) -> &[Dual] {
        &self.fields[field as usize]
    }

    #[inline(always)]
    fn offset(&self, field: Field, index: Index) -> usize {
        let n = self.n;
        match (field, index) {
            (_, Index::Scalar) => 0,
            (_, Index::Entry(i)) => i,
            (Field::Dh, Index::Pair(r, i)) => r * n + i,
            (_, Index::Pair(i, j)) => i * n + j,
            (_, Index::Stacked(r, i, j)) => (r * n + i) * n + j,
        }
    }

    /// Output `at`.
    #[inline]
    pub fn get(&self, at: Output) -> Dual {
        let (field, index) = at.slot();
        self.fields[field as usize][self.offset(field, index)]
    }
}

impl Sink<Dual> for DualOutputs {
    #[inline]
    fn add(&mut self, at: Output, x: Dual) {
        let (field, index) = at.slot();
        let o = self.offset(field, index);
        self.fields[field as usize][o] += x;
    }

    #[inline(always)]
    fn weight(&self, r: usize) -> Dual {
        self.weights[r]
    }
}

/// A value with its derivatives along `K` directions at once, `v + Σ_l d_l ε_l`
/// (`ε_l ε_m = 0`): forward-mode differentiation in lanes, the value's work done once for
/// all of them (the continuous linearisation seeds [`LANES`] directions a sweep).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jet<const K: usize> {
    /// The value.
    pub v: f64,
    /// Its derivative along each direction.
    pub d: [f64; K],
}

/// The directions one [`Jet`] sweep carries.
pub const LANES: usize = 8;

impl<const K: usize> Default for Jet<K> {
    fn default() -> Self {
        Jet {
            v: 0.0,
            d: [0.0; K],
        }
    }
}

impl<const K: usize> Jet<K> {
    /// `v` with no derivative.
    #[inline(always)]
    pub fn constant(v: f64) -> Self {
        Jet { v, d: [0.0; K] }
    }

    /// `v` with `d = s·e` (each lane scaled).
    #[inline(always)]
    fn chain(v: f64, s: f64, e: &[f64; K]) -> Self {
        Jet {
            v,
            d: e.map(|x| s * x),
        }
    }

    /// `op` on the values and lane by lane on the derivatives (a linear operation).
    #[inline(always)]
    fn lanewise(self, o: Self, op: impl Fn(f64, f64) -> f64) -> Self {
        Jet {
            v: op(self.v, o.v),
            d: std::array::from_fn(|l| op(self.d[l], o.d[l])),
        }
    }
}

impl<const K: usize> Add for Jet<K> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.lanewise(o, |a, b| a + b)
    }
}

impl<const K: usize> Sub for Jet<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.lanewise(o, |a, b| a - b)
    }
}

impl<const K: usize> Mul for Jet<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut d = [0.0; K];
        for l in 0..K {
            d[l] = self.d[l] * o.v + self.v * o.d[l];
        }
        Jet { v: self.v * o.v, d }
    }
}

impl<const K: usize> Neg for Jet<K> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Jet {
            v: -self.v,
            d: self.d.map(|x| -x),
        }
    }
}

impl<const K: usize> AddAssign for Jet<K> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}

impl<const K: usize> SubAssign for Jet<K> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}

impl<const K: usize> Scalar for Jet<K> {
    #[inline(always)]
    fn constant(x: f64) -> Self {
        Jet::constant(x)
    }

    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.v.sin_cos();
        (Jet::chain(s, c, &self.d), Jet::chain(c, -s, &self.d))
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        let r = self.v.sqrt();
        Jet::chain(r, 0.5 / r, &self.d)
    }

    #[inline(always)]
    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        Jet::chain(r, -r * r, &self.d)
    }
}

/// The inverse dynamics' outputs over [`Jet`]s ([`crate::kernel::inverse_dynamics`]: `L`,
/// `DlDq`, `Force`, `Tau`; with constraints [`crate::kernel::constraints`]' `Dh` and
/// `DhDot`; the rest ignored), with the accelerations it reads.
#[derive(Clone, Debug)]
pub struct JetOutputs<const K: usize> {
    /// `L`.
    pub l: Jet<K>,
    /// `∂L/∂q` of the springs.
    pub dl_dq: Vec<Jet<K>>,
    /// The model's own forces.
    pub force: Vec<Jet<K>>,
    /// The bodies' `τ`.
    pub tau: Vec<Jet<K>>,
    /// The constraints' `Dh`, row-major (row `r` at `r·n`): empty without constraints.
    pub dh: Vec<Jet<K>>,
    /// The constraints' `q̇ᵀD²h q̇`.
    pub dh_dot: Vec<Jet<K>>,
    /// The number of variables (`dh`'s row length).
    n: usize,
    /// The accelerations the evaluation reads.
    pub accelerations: Vec<f64>,
    /// Generated code's storage between its functions (not part of the outputs).
    #[doc(hidden)]
    pub scratch: Scratch<Jet<K>>,
}

impl<const K: usize> JetOutputs<K> {
    /// Zeros for `n` variables and `rows` constraint equations.
    pub fn new(n: usize, rows: usize) -> Self {
        JetOutputs {
            l: Jet::default(),
            dl_dq: vec![Jet::default(); n],
            force: vec![Jet::default(); n],
            tau: vec![Jet::default(); n],
            dh: vec![Jet::default(); rows * n],
            dh_dot: vec![Jet::default(); rows],
            n,
            accelerations: vec![0.0; n],
            scratch: Scratch::default(),
        }
    }

    /// Zeroes the outputs.
    pub fn clear(&mut self) {
        self.l = Jet::default();
        for v in [
            &mut self.dl_dq,
            &mut self.force,
            &mut self.tau,
            &mut self.dh,
            &mut self.dh_dot,
        ] {
            v.fill(Jet::default());
        }
    }
}

impl<const K: usize> Sink<Jet<K>> for JetOutputs<K> {
    #[inline]
    fn add(&mut self, at: Output, x: Jet<K>) {
        // Stored as the one table places them (`Output::slot`); other fields ignored.
        match at.slot() {
            (Field::L, _) => self.l += x,
            (Field::DlDq, Index::Entry(i)) => self.dl_dq[i] += x,
            (Field::Force, Index::Entry(i)) => self.force[i] += x,
            (Field::Tau, Index::Entry(i)) => self.tau[i] += x,
            (Field::Dh, Index::Pair(r, i)) => self.dh[r * self.n + i] += x,
            (Field::DhDot, Index::Entry(r)) => self.dh_dot[r] += x,
            _ => {}
        }
    }

    #[inline(always)]
    fn acceleration(&self, i: usize) -> f64 {
        self.accelerations[i]
    }
}
