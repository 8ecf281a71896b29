//! What an evaluation produces, by name ([`Output`]), where it is stored ([`Output::slot`]: the
//! one table the runtime's storage and the compiler's emission both read), and where an
//! evaluation puts it ([`Sink`]).

use crate::plan::TreePlan;
use crate::scalar::Scalar;

/// One scalar that an evaluation produces. Every evaluation adds its contributions into a
/// [`Sink`] by these names, so a new term is one more contribution, not a new interface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Output {
    /// `L` (eq. (15)), springs' potentials included.
    L,
    /// The total energy `E = T + V` (springs' potentials included), from the energy
    /// evaluation alone ([`crate::kernel::energy`]); the other evaluations leave it out.
    Energy,
    /// `∂L/∂q_i` (eq. (16)).
    DlDq(usize),
    /// `∂L/∂q̇_i`.
    DlDdq(usize),
    /// `M_ij = ∂²L/∂q̇_i∂q̇_j` (eq. (18)).
    Mass(usize, usize),
    /// `∂²L/∂q̇_i∂q_j` (eq. (17)).
    D2lDdqDq(usize, usize),
    /// `∂²L/∂q_i∂q_j`.
    D2lDqDq(usize, usize),
    /// The model's own generalized force `F_i(q, q̇)` (damping, dampers).
    Force(usize),
    /// `∂F_i/∂q_j`.
    DforceDq(usize, usize),
    /// `∂F_i/∂q̇_j`.
    DforceDdq(usize, usize),
    /// Constraint row `h_r(q)`.
    H(usize),
    /// `∂h_r/∂q_i`.
    Dh(usize, usize),
    /// `q̇ᵀ (∂²h_r/∂q²) q̇`, the acceleration-level constraint's velocity term.
    DhDot(usize),
    /// `∂²h_r/∂q_i∂q_j`.
    D2h(usize, usize, usize),
    /// `Σ_r w_r ∂²h_r/∂q_i∂q_j`: the rows' Hessians weighted (by a step's multipliers), on
    /// the dynamic variables' columns `j` ([`Weighted`]).
    WeightedD2h(usize, usize),
    /// The bodies' inverse dynamics `τ_i = [M q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q]_i` at given
    /// accelerations (recursive Newton–Euler, [`crate::kernel::inverse_dynamics`]; springs and forces not
    /// included).
    Tau(usize),
}

/// Where evaluations put what they produce: the interpreted system's matrices, or the
/// compiler's record of which traced value lands in which output. Contributions add up;
/// `set` is for an output written first and once (the tree's own terms, before springs and
/// forces add to them), and may skip reading the old value.
pub trait Sink<S> {
    /// Adds `x` to the output `at`.
    fn add(&mut self, at: Output, x: S);

    /// Writes output `at`, which no other contribution touches (default: adds).
    fn set(&mut self, at: Output, x: S) {
        self.add(at, x)
    }

    /// The acceleration `q̈_i` an inverse-dynamics evaluation is asked for, where the sink
    /// carries it (the generated code's one input besides the state; default zero).
    fn acceleration(&self, i: usize) -> f64 {
        let _ = i;
        0.0
    }

    /// Constraint row `r`'s weight in a weighted Hessian ([`Output::WeightedD2h`]), where
    /// the sink carries it (the generated weighted evaluation's input; default zero).
    fn weight(&self, r: usize) -> S
    where
        S: Scalar,
    {
        let _ = r;
        S::zero()
    }
}

/// A field of `Terms` or `ConstraintTerms` that outputs are stored in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Field {
    /// `Terms::l`.
    L,
    /// `Terms::total_energy`.
    Energy,
    /// `Terms::dl_dq`.
    DlDq,
    /// `Terms::dl_ddq`.
    DlDdq,
    /// `Terms::mass`.
    Mass,
    /// `Terms::d2l_ddq_dq`.
    D2lDdqDq,
    /// `Terms::d2l_dq_dq`.
    D2lDqDq,
    /// `Terms::force`.
    Force,
    /// `Terms::dforce_dq`.
    DforceDq,
    /// `Terms::dforce_ddq`.
    DforceDdq,
    /// `ConstraintTerms::h`.
    H,
    /// `ConstraintTerms::dh`.
    Dh,
    /// `ConstraintTerms::dh_dot`.
    DhDot,
    /// `ConstraintTerms::d2h`.
    D2h,
    /// `ConstraintTerms::weighted_d2h`.
    WeightedD2h,
    /// The inverse dynamics' `τ` (`JetOutputs::tau`; no f64 storage keeps it).
    Tau,
}

impl Field {
    /// The field's name in its struct (what generated code writes to).
    pub fn name(self) -> &'static str {
        match self {
            Field::L => "l",
            Field::Energy => "total_energy",
            Field::DlDq => "dl_dq",
            Field::DlDdq => "dl_ddq",
            Field::Mass => "mass",
            Field::D2lDdqDq => "d2l_ddq_dq",
            Field::D2lDqDq => "d2l_dq_dq",
            Field::Force => "force",
            Field::DforceDq => "dforce_dq",
            Field::DforceDdq => "dforce_ddq",
            Field::H => "h",
            Field::Dh => "dh",
            Field::DhDot => "dh_dot",
            Field::D2h => "d2h",
            Field::WeightedD2h => "weighted_d2h",
            Field::Tau => "tau",
        }
    }
}

/// Where in its field an output sits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Index {
    /// The field is one number.
    Scalar,
    /// Entry `i` of a vector.
    Entry(usize),
    /// Entry `(i, j)` of a matrix.
    Pair(usize, usize),
    /// Entry `(i, j)` of matrix `r` of a list.
    Stacked(usize, usize, usize),
}

impl Output {
    /// The field and index this output is stored at.
    #[inline(always)]
    pub fn slot(self) -> (Field, Index) {
        use Index::{Entry, Pair, Scalar, Stacked};
        match self {
            Output::L => (Field::L, Scalar),
            Output::Energy => (Field::Energy, Scalar),
            Output::DlDq(i) => (Field::DlDq, Entry(i)),
            Output::DlDdq(i) => (Field::DlDdq, Entry(i)),
            Output::Mass(i, j) => (Field::Mass, Pair(i, j)),
            Output::D2lDdqDq(i, j) => (Field::D2lDdqDq, Pair(i, j)),
            Output::D2lDqDq(i, j) => (Field::D2lDqDq, Pair(i, j)),
            Output::Force(i) => (Field::Force, Entry(i)),
            Output::DforceDq(i, j) => (Field::DforceDq, Pair(i, j)),
            Output::DforceDdq(i, j) => (Field::DforceDdq, Pair(i, j)),
            Output::H(r) => (Field::H, Entry(r)),
            Output::Dh(r, i) => (Field::Dh, Pair(r, i)),
            Output::DhDot(r) => (Field::DhDot, Entry(r)),
            Output::D2h(r, i, j) => (Field::D2h, Stacked(r, i, j)),
            Output::WeightedD2h(i, j) => (Field::WeightedD2h, Pair(i, j)),
            Output::Tau(i) => (Field::Tau, Entry(i)),
        }
    }
}

/// A sink in front of another that sums the constraint rows' Hessians weighted, `D²h_r`'s
/// entry `(i, j)` times `weights[r]` into [`Output::WeightedD2h`]`(i, j)` for the columns `j`
/// that `columns` keeps, and drops `q̇ᵀD²h q̇`; every other output passes on. Run over a
/// constraint evaluation at `Order::Full`, it gives `h`, `Dh` and `Σ_r w_r D²h_r` without
/// forming any row's Hessian: what a step's first derivatives read at `q₁`
/// (`System::weighted_constraint_hessian`, docs/derivations.md §9).
pub struct Weighted<'a, S, K> {
    /// One weight per constraint row.
    pub weights: &'a [S],
    /// The columns kept, one flag per variable.
    pub columns: &'a [bool],
    /// Where everything goes.
    pub inner: &'a mut K,
}

impl<S: Scalar, K: Sink<S>> Sink<S> for Weighted<'_, S, K> {
    #[inline(always)]
    fn add(&mut self, at: Output, x: S) {
        match at {
            Output::D2h(r, i, j) => {
                if self.columns[j] {
                    self.inner
                        .add(Output::WeightedD2h(i, j), self.weights[r] * x);
                }
            }
            Output::DhDot(_) => {}
            _ => self.inner.add(at, x),
        }
    }
}

/// A sink in front of another that takes what the sweeps produce in full coordinates — the
/// model's variables, then one per mimic frame ([`crate::Follower`]) — to the model's
/// variables.
/// With `q_full = A q + b` (a follower's row of `A` its multiplier in its leader's column),
/// `L(q, q̇) = L_full(A q + b, A q̇)`, so every first derivative is `Aᵀ` times the full one and
/// every second derivative `Aᵀ (·) A`: an output at full indices adds, times the product of
/// their multipliers, into the output at their model variables (docs/derivations.md §12).
/// Outputs with no variable index pass on as they are; with followers every indexed `set`
/// becomes an `add` (several full entries land in one), so the storage is cleared first, as
/// every evaluation's is. Without followers, everything passes on.
pub struct Contract<'a, K> {
    /// The plan whose followers ([`TreePlan::reduced`]) are taken back.
    pub plan: &'a TreePlan,
    /// Where everything goes.
    pub inner: &'a mut K,
}

impl<'a, K> Contract<'a, K> {
    /// In front of `inner`, for `plan`'s followers.
    #[inline(always)]
    pub fn new(plan: &'a TreePlan, inner: &'a mut K) -> Self {
        Contract { plan, inner }
    }

    /// Full variable `i` as the model's variable, its factor `∂q_full,i/∂q` multiplied into
    /// `factor`.
    #[inline(always)]
    fn reduce(&self, i: usize, factor: &mut f64) -> usize {
        let (variable, m) = self.plan.reduced(i);
        *factor *= m;
        variable
    }

    /// `at` at the model's variables, and the product of the multipliers.
    #[inline(always)]
    fn reduced(&self, at: Output) -> (Output, f64) {
        use Output::*;
        let mut f = 1.0;
        let at = match at {
            L | Energy | H(_) | DhDot(_) => at,
            DlDq(i) => DlDq(self.reduce(i, &mut f)),
            DlDdq(i) => DlDdq(self.reduce(i, &mut f)),
            Force(i) => Force(self.reduce(i, &mut f)),
            Tau(i) => Tau(self.reduce(i, &mut f)),
            Mass(i, j) => Mass(self.reduce(i, &mut f), self.reduce(j, &mut f)),
            D2lDdqDq(i, j) => D2lDdqDq(self.reduce(i, &mut f), self.reduce(j, &mut f)),
            D2lDqDq(i, j) => D2lDqDq(self.reduce(i, &mut f), self.reduce(j, &mut f)),
            DforceDq(i, j) => DforceDq(self.reduce(i, &mut f), self.reduce(j, &mut f)),
            DforceDdq(i, j) => DforceDdq(self.reduce(i, &mut f), self.reduce(j, &mut f)),
            Dh(r, i) => Dh(r, self.reduce(i, &mut f)),
            D2h(r, i, j) => D2h(r, self.reduce(i, &mut f), self.reduce(j, &mut f)),
            WeightedD2h(i, j) => WeightedD2h(self.reduce(i, &mut f), self.reduce(j, &mut f)),
        };
        (at, f)
    }
}

impl<S: Scalar, K: Sink<S>> Sink<S> for Contract<'_, K> {
    #[inline(always)]
    fn add(&mut self, at: Output, x: S) {
        if self.plan.followers.is_empty() {
            return self.inner.add(at, x);
        }
        match self.reduced(at) {
            (at, 1.0) => self.inner.add(at, x),
            (at, f) => self.inner.add(at, x * S::constant(f)),
        }
    }

    #[inline(always)]
    fn set(&mut self, at: Output, x: S) {
        let unindexed = matches!(
            at,
            Output::L | Output::Energy | Output::H(_) | Output::DhDot(_)
        );
        if self.plan.followers.is_empty() || unindexed {
            self.inner.set(at, x)
        } else {
            self.add(at, x)
        }
    }

    fn acceleration(&self, i: usize) -> f64 {
        self.inner.acceleration(i)
    }

    fn weight(&self, r: usize) -> S
    where
        S: Scalar,
    {
        self.inner.weight(r)
    }
}

/// Storage the code `tree_model!` generates keeps between evaluations: the values its
/// functions pass to one another (a generated evaluation is cut into functions of a few
/// hundred statements). It lives in the outputs an evaluation fills, so it is allocated once,
/// on first use, and never cleared: every entry is written before it is read. It is not part
/// of the outputs' value (equal whatever it holds).
#[derive(Clone, Default)]
pub struct Scratch<T>(Vec<T>);

impl<T: Copy + Default> Scratch<T> {
    /// The first `K` entries as an array, grown (once) to hold them.
    #[inline]
    pub fn array<const K: usize>(&mut self) -> &mut [T; K] {
        if self.0.len() < K {
            self.0.resize(K, T::default());
        }
        match self.0.first_chunk_mut() {
            Some(array) => array,
            None => unreachable!("the scratch was just grown to {K} entries"),
        }
    }
}

impl<T> PartialEq for Scratch<T> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl<T> std::fmt::Debug for Scratch<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Scratch({} entries)", self.0.len())
    }
}

/// Zeroes the entries `(i, j)`, `i` and `j` both among `vars`, of the `n × n` column-major
/// `block`: a constraint row's `D²h`, which an evaluation writes there alone.
pub fn clear_among<T: Copy>(block: &mut [T], n: usize, vars: &[usize], zero: T) {
    for &j in vars {
        let column = &mut block[j * n..(j + 1) * n];
        for &i in vars {
            column[i] = zero;
        }
    }
}
