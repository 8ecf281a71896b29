//! Forward-mode dual numbers `v + d·ε` (ε² = 0): the kernel evaluated over them gives, beside
//! every output, its exact derivative along one direction of `(q, q̇)` — how the continuous
//! linearisation differentiates `M`, `∂L/∂q`, `Dh`, … without finite differences.

use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

use crate::outputs::{Field, Index, Output, Scratch, Sink};
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
    /// Generated code's storage between its functions (not part of the outputs).
    #[doc(hidden)]
    pub scratch: Scratch<Dual>,
    /// The accelerations an inverse-dynamics evaluation reads
    /// ([`crate::system::System::inverse_dynamics_dual`] sets them; not part of the outputs).
    pub accelerations: Vec<f64>,
}

/// Every field, in declaration order (so `field as usize` indexes it).
const FIELDS: [Field; 14] = [
    Field::L,
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
    Field::Tau,
];

impl DualOutputs {
    /// Zeros for `n` variables and `m` constraint rows.
    pub fn new(n: usize, m: usize) -> Self {
        let size = |f: Field| match f {
            Field::L => 1,
            Field::DlDq | Field::DlDdq | Field::Force | Field::Tau => n,
            Field::Mass | Field::D2lDdqDq | Field::D2lDqDq | Field::DforceDq | Field::DforceDdq => {
                n * n
            }
            Field::H | Field::DhDot => m,
            Field::Dh => m * n,
            Field::D2h => m * n * n,
        };
        DualOutputs {
            n,
            fields: FIELDS
                .iter()
                .map(|&f| vec![Dual::default(); size(f)])
                .collect(),
            scratch: Scratch::default(),
            accelerations: vec![0.0; n],
        }
    }

    /// Zeroes every output.
    pub fn clear(&mut self) {
        for f in &mut self.fields {
            f.fill(Dual::default());
        }
    }

    /// Zeroes the outputs of `fields` alone (an evaluation that writes only those need not
    /// pay for clearing the matrices).
    pub fn clear_fields(&mut self, fields: &[Field]) {
        for &f in fields {
            self.fields[f as usize].fill(Dual::default());
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
    fn acceleration(&self, i: usize) -> f64 {
        self.accelerations[i]
    }
}
