//! The one trait every simulated system implements — the interpreted tree and the code
//! `tree_model!` generates — and the Lagrangian terms it yields.

use nalgebra::{
    allocator::Allocator, DMatrix, DVector, DefaultAllocator, Dim, OMatrix, OVector, U1,
};
use tree_model::Motion;

use tree_kernel::se3::Pose;
pub use tree_kernel::Order;
use tree_kernel::{clear_among, Field, Index, Output, Scratch, Sink};
use tree_kernel::{Dual, DualOutputs, Jet, JetOutputs, LANES};
use tree_kernel::{ElementForces, Lanes, WIDTH};

/// A vector over the system's configuration variables.
pub type Vector<N> = OVector<f64, N>;
/// A square matrix over the system's configuration variables.
pub type Matrix<N> = OMatrix<f64, N, N>;

/// The Lagrangian and its derivatives at one state `(q, q̇)`; entries above the requested
/// [`Order`] are left as they were.
#[derive(Clone, Debug, PartialEq)]
pub struct Terms<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// `L = Σ_k ½ v_kᵀ M_k v_k + m_k γ·p_k` (eq. (15), gravity sign as in docs/derivations.md §2).
    pub l: f64,
    /// The total energy `E = T + V`, written by [`System::energy`] alone (zero after
    /// [`Terms::clear`]).
    pub total_energy: f64,
    /// `∂L/∂q` (eq. (16)).
    pub dl_dq: Vector<N>,
    /// `∂L/∂q̇`, the generalized momentum.
    pub dl_ddq: Vector<N>,
    /// The mass matrix `M = ∂²L/∂q̇∂q̇` (eq. (18)).
    pub mass: Matrix<N>,
    /// Row i, column j: `∂²L/∂q̇_i∂q_j` (eq. (17)).
    pub d2l_ddq_dq: Matrix<N>,
    /// `∂²L/∂q∂q`.
    pub d2l_dq_dq: Matrix<N>,
    /// The model's own generalized force `F(q, q̇)`: damping and dampers.
    pub force: Vector<N>,
    /// `∂F/∂q` (at `Order::Full`).
    pub dforce_dq: Matrix<N>,
    /// `∂F/∂q̇` (at `Order::Full`).
    pub dforce_ddq: Matrix<N>,
    /// Which entries of `dforce_dq`/`dforce_ddq` the last evaluation may have written; all
    /// others are zero (consumers and `clear` skip them).
    pub force_derivatives: Sparsity,
    /// Generated code's storage between its functions (not part of the terms' value).
    #[doc(hidden)]
    pub scratch: Scratch<f64>,
    /// Which compiled evaluation last assigned the n × n matrices, when these terms keep its
    /// zeros ([`Terms::keep_zeros`]; not part of the terms' value).
    assigned: Assigned,
}

/// The compiled evaluation (its model's key and its order) whose assigned entries are the
/// only non-zeros of a [`Terms`]' n × n matrices, if the terms are kept for it: a compiled
/// evaluation assigns the same entries on every call and leaves the others alone, so from one
/// call to the next at the same order only the vectors need clearing (what that saves:
/// docs/benchmarks.md, stop 39). Equal whatever it holds, and a
/// clone keeps nothing (the copy's owner may write where the evaluation does not).
#[derive(Debug, Default)]
struct Assigned {
    keeps: bool,
    by: Option<(usize, Order)>,
}

impl Assigned {
    /// Whether these outputs are kept and model `key`'s evaluation at `order` wrote them last.
    fn holds(&self, key: usize, order: Order) -> bool {
        self.keeps && self.by == Some((key, order))
    }
}

impl Clone for Assigned {
    fn clone(&self) -> Self {
        Assigned::default()
    }
}

impl PartialEq for Assigned {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Where a pair of matrices may be non-zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Sparsity {
    /// All zero.
    #[default]
    Zero,
    /// Only `dforce_ddq`'s diagonal (per-variable damping).
    Diagonal,
    /// Anywhere (dampers).
    Dense,
}

impl<N: Dim> Terms<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// All zeros, sized for `n`.
    pub fn zeros(n: N) -> Self {
        Terms {
            l: 0.0,
            total_energy: 0.0,
            dl_dq: Vector::zeros_generic(n, U1),
            dl_ddq: Vector::zeros_generic(n, U1),
            mass: Matrix::zeros_generic(n, n),
            d2l_ddq_dq: Matrix::zeros_generic(n, n),
            d2l_dq_dq: Matrix::zeros_generic(n, n),
            force: Vector::zeros_generic(n, U1),
            dforce_dq: Matrix::zeros_generic(n, n),
            dforce_ddq: Matrix::zeros_generic(n, n),
            force_derivatives: Sparsity::Zero,
            scratch: Scratch::default(),
            assigned: Assigned::default(),
        }
    }

    /// Lets a compiled evaluation into these terms skip clearing the n × n matrices when the
    /// last evaluation into them was its own at the same order ([`Assigned`]). For terms no
    /// one else writes to (an integrator's own); plain [`Terms::clear`] still clears all.
    #[doc(hidden)]
    pub fn keep_zeros(&mut self) {
        self.assigned.keeps = true;
    }

    /// Before a compiled evaluation of the model `key` at `order` that assigns a fixed set
    /// of entries: [`Terms::clear`], but the n × n matrices where they hold that same
    /// evaluation's last (kept terms only).
    #[doc(hidden)]
    pub fn begin_assigned(&mut self, key: usize, order: Order) {
        if order >= Order::Dynamics && self.assigned.holds(key, order) {
            self.clear_parts(order, false);
        } else {
            self.clear(order);
        }
    }

    /// After the evaluation [`Terms::begin_assigned`] began (one of the first order writes
    /// no matrix, and leaves them as they were).
    #[doc(hidden)]
    pub fn end_assigned(&mut self, key: usize, order: Order) {
        if order >= Order::Dynamics {
            self.assigned.by = Some((key, order));
        }
    }

    /// Zeroes what `order` asks for, ready to accumulate. Each buffer is one contiguous
    /// `memset` (nalgebra's element iterator costs several times that on 40×40 matrices).
    pub fn clear(&mut self, order: Order) {
        self.clear_parts(order, true);
        if order >= Order::Dynamics {
            self.assigned.by = None;
        }
    }

    /// [`Terms::clear`], `M`, `∂²L/∂q̇∂q` and `∂²L/∂q²` only with `matrices` (the forces'
    /// derivatives always).
    fn clear_parts(&mut self, order: Order, matrices: bool) {
        self.l = 0.0;
        self.total_energy = 0.0;
        self.dl_dq.as_mut_slice().fill(0.0);
        self.dl_ddq.as_mut_slice().fill(0.0);
        self.force.as_mut_slice().fill(0.0);
        if order >= Order::Dynamics && matrices {
            self.mass.as_mut_slice().fill(0.0);
            self.d2l_ddq_dq.as_mut_slice().fill(0.0);
        }
        if order >= Order::Full {
            if matrices {
                self.d2l_dq_dq.as_mut_slice().fill(0.0);
            }
            match self.force_derivatives {
                Sparsity::Zero => {}
                Sparsity::Diagonal => self.dforce_ddq.fill_diagonal(0.0),
                Sparsity::Dense => {
                    self.dforce_dq.as_mut_slice().fill(0.0);
                    self.dforce_ddq.as_mut_slice().fill(0.0);
                }
            }
            self.force_derivatives = Sparsity::Zero;
        }
    }

    /// Total energy `E = q̇·∂L/∂q̇ − L` (the Legendre transform; `T + V` here).
    pub fn energy(&self, dq: &Vector<N>) -> f64 {
        self.dl_ddq.dot(dq) - self.l
    }
}

/// Each constraint row's variables ([`System::constraint_variables`]), ascending, when the
/// system names them for every row; empty otherwise (unknown).
pub(crate) fn row_variables<S: System>(sys: &S) -> Vec<Vec<usize>>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let known: Option<Vec<Vec<usize>>> = (0..sys.constraint_count())
        .map(|r| sys.constraint_variables(r).map(<[usize]>::to_vec))
        .collect();
    known.unwrap_or_default()
}

impl<N: Dim> Sink<f64> for Terms<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    #[inline(always)]
    fn add(&mut self, at: Output, x: f64) {
        if let Some(entry) = self.entry(at) {
            *entry += x;
        }
    }

    #[inline(always)]
    fn set(&mut self, at: Output, x: f64) {
        if let Some(entry) = self.entry(at) {
            *entry = x;
        }
    }
}

impl<N: Dim> Terms<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// Where output `at` is stored ([`Output::slot`]); `None` for the constraints' outputs.
    /// Writing a force derivative widens [`Terms::force_derivatives`].
    #[inline(always)]
    fn entry(&mut self, at: Output) -> Option<&mut f64> {
        fn matrix<N: Dim>(m: &mut Matrix<N>, index: Index) -> Option<&mut f64>
        where
            DefaultAllocator: Allocator<N, N>,
        {
            match index {
                Index::Pair(i, j) => Some(&mut m[(i, j)]),
                _ => None,
            }
        }
        let (field, index) = at.slot();
        match (field, index) {
            (Field::L, _) => Some(&mut self.l),
            (Field::Energy, _) => Some(&mut self.total_energy),
            (Field::DlDq, Index::Entry(i)) => Some(&mut self.dl_dq[i]),
            (Field::DlDdq, Index::Entry(i)) => Some(&mut self.dl_ddq[i]),
            (Field::Force, Index::Entry(i)) => Some(&mut self.force[i]),
            (Field::Mass, index) => matrix(&mut self.mass, index),
            (Field::D2lDdqDq, index) => matrix(&mut self.d2l_ddq_dq, index),
            (Field::D2lDqDq, index) => matrix(&mut self.d2l_dq_dq, index),
            (Field::DforceDq, index) => {
                self.force_derivatives = Sparsity::Dense;
                matrix(&mut self.dforce_dq, index)
            }
            (Field::DforceDdq, index) => {
                let diagonal = matches!(index, Index::Pair(i, j) if i == j);
                let at = if diagonal {
                    Sparsity::Diagonal
                } else {
                    Sparsity::Dense
                };
                self.force_derivatives = self.force_derivatives.max(at);
                matrix(&mut self.dforce_ddq, index)
            }
            _ => None,
        }
    }
}

/// The holonomic constraints `h(q) = 0` and their derivatives at one state: one row per
/// constraint equation, one column per variable (all variables, kinematic included).
#[derive(Clone, Debug, PartialEq)]
pub struct ConstraintTerms {
    /// `h(q)`.
    pub h: DVector<f64>,
    /// `Dh = ∂h/∂q`, rows: constraint equations.
    pub dh: DMatrix<f64>,
    /// `q̇ᵀ D²h_r q̇` for each row (from `Order::Dynamics` on).
    pub dh_dot: DVector<f64>,
    /// `D²h_r = ∂²h_r/∂q²` for each row (at `Order::Full`).
    pub d2h: Vec<DMatrix<f64>>,
    /// `Σ_r w_r D²h_r` on the dynamic variables' columns (n × n, from
    /// [`System::weighted_constraint_hessian`]; 0 × 0 before its first call). The other
    /// columns are not written: zero as the matrix is made, unless written by the caller.
    pub weighted_d2h: DMatrix<f64>,
    /// The weights `w` of [`Self::weighted_d2h`] (an input of the generated code, which reads
    /// it here).
    #[doc(hidden)]
    pub weights: Vec<f64>,
    /// Generated code's storage between its functions (not part of the terms' value).
    #[doc(hidden)]
    pub scratch: Scratch<f64>,
    /// Per row, the variables its `D²h` block can be non-zero on (empty: any).
    variables: Vec<Vec<usize>>,
    /// Which compiled weighted evaluation last assigned [`Self::weighted_d2h`], when these
    /// terms keep its zeros ([`ConstraintTerms::keep_zeros`]; not part of their value).
    assigned: Assigned,
}

impl ConstraintTerms {
    /// Zeros for `rows` equations over `n` variables.
    pub fn zeros(rows: usize, n: usize) -> Self {
        ConstraintTerms {
            h: DVector::zeros(rows),
            dh: DMatrix::zeros(rows, n),
            dh_dot: DVector::zeros(rows),
            d2h: vec![DMatrix::zeros(n, n); rows],
            weighted_d2h: DMatrix::zeros(0, 0),
            weights: Vec::new(),
            scratch: Scratch::default(),
            variables: Vec::new(),
            assigned: Assigned::default(),
        }
    }

    /// Lets a compiled weighted evaluation into these terms skip clearing
    /// [`Self::weighted_d2h`] when its own evaluation wrote it last ([`Assigned`]). For terms
    /// no one else writes to (a linearisation's own).
    #[doc(hidden)]
    pub fn keep_zeros(&mut self) {
        self.assigned.keeps = true;
    }

    /// [`Self::weigh`] before a compiled weighted evaluation of the model `key`, which
    /// assigns the entries the constraints reach and nothing else: `weighted_d2h` cleared
    /// unless these terms are kept and that evaluation wrote it last.
    #[doc(hidden)]
    pub fn weigh_assigned(&mut self, weights: &[f64], key: usize) {
        let own = self.assigned.holds(key, Order::Full);
        self.weigh(weights, !own);
        self.assigned.by = Some((key, Order::Full));
    }

    /// Ready for a weighted Hessian ([`System::weighted_constraint_hessian`]): `weights` kept
    /// as the evaluation's input, `h` and `Dh` zeroed, and [`Self::weighted_d2h`] sized n × n
    /// (allocated on the first call only) — zeroed too if `clear` (for an evaluation that
    /// accumulates). Panics unless there is one weight per constraint row (a caller's error,
    /// not input's).
    pub fn weigh(&mut self, weights: &[f64], clear: bool) {
        assert_eq!(weights.len(), self.rows(), "one weight per constraint row");
        let n = self.dh.ncols();
        self.clear(Order::First);
        self.assigned.by = None;
        self.weights.clear();
        self.weights.extend_from_slice(weights);
        if self.weighted_d2h.shape() != (n, n) {
            self.weighted_d2h = DMatrix::zeros(n, n);
        } else if clear {
            self.weighted_d2h.as_mut_slice().fill(0.0);
        }
    }

    /// Zeros for `sys`'s constraints that know each row's variables
    /// ([`System::constraint_variables`]): clearing `D²h` zeroes each row's block on them
    /// alone (trep's Puppet's six strings: at most 13² entries each instead of 40²). An evaluation
    /// never writes outside those blocks, so entries there stay as they are (zero, unless
    /// the caller wrote them).
    pub fn of<S: System>(sys: &S) -> Self
    where
        DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
    {
        Self::zeros(sys.constraint_count(), sys.dof()).with_variables(row_variables(sys))
    }

    /// These terms with row r's `D²h` block known to lie on `variables[r]` (ascending), as
    /// [`Self::of`] makes them.
    pub(crate) fn with_variables(mut self, variables: Vec<Vec<usize>>) -> Self {
        debug_assert_eq!(variables.len(), self.rows());
        self.variables = variables;
        self
    }

    /// The variables row `r`'s `D²h` block can be non-zero on, ascending, when known
    /// ([`Self::of`]).
    pub fn variables(&self, r: usize) -> Option<&[usize]> {
        self.variables.get(r).map(Vec::as_slice)
    }

    /// Number of constraint equations.
    pub fn rows(&self) -> usize {
        self.h.len()
    }

    /// Zeroes what `order` asks for, ready to accumulate.
    pub fn clear(&mut self, order: Order) {
        self.h.as_mut_slice().fill(0.0);
        self.dh.as_mut_slice().fill(0.0);
        if order >= Order::Dynamics {
            self.dh_dot.as_mut_slice().fill(0.0);
        }
        if order >= Order::Full {
            if self.variables.is_empty() {
                self.d2h.iter_mut().for_each(|m| m.as_mut_slice().fill(0.0));
            }
            for (m, vars) in self.d2h.iter_mut().zip(&self.variables) {
                let n = m.nrows();
                clear_among(m.as_mut_slice(), n, vars, 0.0);
            }
        }
    }

    /// `max |h_r|`, 0 without constraints.
    pub fn violation(&self) -> f64 {
        self.h.amax()
    }
}

impl Sink<f64> for ConstraintTerms {
    #[inline(always)]
    fn add(&mut self, at: Output, x: f64) {
        let entry = match at.slot() {
            (Field::H, Index::Entry(r)) => &mut self.h[r],
            (Field::Dh, Index::Pair(r, i)) => &mut self.dh[(r, i)],
            (Field::DhDot, Index::Entry(r)) => &mut self.dh_dot[r],
            (Field::D2h, Index::Stacked(r, i, j)) => &mut self.d2h[r][(i, j)],
            (Field::WeightedD2h, Index::Pair(i, j)) => &mut self.weighted_d2h[(i, j)],
            _ => return,
        };
        *entry += x;
    }
}

/// The [`System`] methods that describe the model — sizes, names, initial state, damping,
/// inputs — for a system that holds its [`tree_model::Model`] in a field `model` and is
/// `Dyn`-sized (the interpreted system and the paper's reference): written once here.
macro_rules! described_by_model {
    () => {
        fn dim(&self) -> nalgebra::Dyn {
            nalgebra::Dyn(self.model.variables.len())
        }

        fn variable_name(&self, i: usize) -> &str {
            &self.model.variables[i].name
        }

        fn frame_count(&self) -> usize {
            self.model.frames.len()
        }

        fn frame_name(&self, k: usize) -> &str {
            &self.model.frames[k].name
        }

        fn initial(&self, i: usize) -> (f64, f64) {
            let v = &self.model.variables[i];
            (v.q0, v.dq0)
        }

        fn damping(&self, i: usize) -> f64 {
            self.model.variables[i].damping
        }

        fn is_angle(&self, i: usize) -> bool {
            self.model.is_angle(i)
        }

        fn input_count(&self) -> usize {
            self.model.inputs.len()
        }

        fn input_name(&self, k: usize) -> &str {
            &self.model.inputs[k].name
        }

        fn input_variable(&self, k: usize) -> usize {
            self.model.inputs[k].variable
        }
    };
}
pub(crate) use described_by_model;

/// A mechanical system in generalized coordinates: a tree whose Lagrangian and derivatives
/// can be evaluated at any state. `N` is `Const<n>` for generated systems (nothing is
/// allocated per evaluation) and `Dyn` for the interpreted one.
pub trait System
where
    DefaultAllocator: Allocator<Self::N> + Allocator<Self::N, Self::N>,
{
    /// The dimension type of the configuration space.
    type N: Dim;

    /// The dimension value (`Const` or `Dyn(n)`).
    fn dim(&self) -> Self::N;

    /// Number of configuration variables.
    fn dof(&self) -> usize {
        self.dim().value()
    }

    /// Name of variable `i`, in the model's order.
    fn variable_name(&self, i: usize) -> &str;

    /// Number of frames (not counting the world frame).
    fn frame_count(&self) -> usize;

    /// Name of frame `k`, in the model's (topological) order.
    fn frame_name(&self, k: usize) -> &str;

    /// The model's initial value `q0` and velocity `dq0` of variable `i`.
    fn initial(&self, i: usize) -> (f64, f64);

    /// The viscous damping coefficient `c_i` (generalized force `−c_i q̇_i`, part of
    /// [`Terms::force`]).
    fn damping(&self, i: usize) -> f64;

    /// The prescribed motion of variable `i` when it is kinematic, `None` when it is dynamic.
    fn motion(&self, i: usize) -> Option<Motion>;

    /// Whether variable `i` drives a rotation (an angle, in rad) rather than a translation
    /// or a constraint's length. Read when setting up (the VI's quarter-turn guard, plots).
    fn is_angle(&self, i: usize) -> bool;

    /// Whether variable `i` is kinematic (prescribed).
    fn is_kinematic(&self, i: usize) -> bool {
        self.motion(i).is_some()
    }

    /// Number of constraint equations.
    fn constraint_count(&self) -> usize;

    /// Name of constraint equation `r`.
    fn constraint_name(&self, r: usize) -> &str;

    /// The variables constraint equation `r` depends on, ascending — its `Dh` row and `D²h`
    /// block are zero outside them — when the system knows them (the default: `None`, any
    /// variable). The interpreted and compiled systems know them from the tree.
    fn constraint_variables(&self, r: usize) -> Option<&[usize]> {
        let _ = r;
        None
    }

    /// Number of inputs `u`: generalized forces on dynamic variables, `B u` with one column
    /// of `B` per input.
    fn input_count(&self) -> usize;

    /// Name of input `k`.
    fn input_name(&self, k: usize) -> &str;

    /// Every input's name, in `u`'s order.
    fn input_names(&self) -> Vec<String> {
        (0..self.input_count())
            .map(|k| self.input_name(k).to_string())
            .collect()
    }

    /// The variable input `k` pushes on (the row of its column of `B`).
    fn input_variable(&self, k: usize) -> usize;

    /// Evaluates the constraints up to `order` at `(q, q̇)` into `out` (sized
    /// `constraint_count() × dof()`).
    fn constraints(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        order: Order,
        out: &mut ConstraintTerms,
    );

    /// `h(q)`, `Dh(q)` and the constraint rows' Hessians summed with `weights` (one per row),
    /// `Σ_r w_r D²h_r(q)`, on the dynamic variables' columns, into `out.weighted_d2h` (n × n;
    /// the kinematic variables' columns are not part of it): the multipliers' term `Σ_s λ_s D²h_s(q₁)` of a
    /// step's first derivatives (docs/derivations.md §9), without forming each row's
    /// Hessian. `out.dh_dot` and `out.d2h` are not outputs of it (what they hold after is
    /// unspecified). The default makes the whole evaluation at `Order::Full` and sums; the
    /// interpreted and generated systems sum as they go ([`tree_kernel::Weighted`]).
    fn weighted_constraint_hessian(
        &mut self,
        q: &Vector<Self::N>,
        weights: &[f64],
        out: &mut ConstraintTerms,
    ) {
        let n = q.len();
        out.weigh(weights, true);
        // `q̇ᵀD²h q̇` is not an output here: any velocity will do (q, with no allocation).
        self.constraints(q, q, Order::Full, out);
        let ConstraintTerms {
            d2h, weighted_d2h, ..
        } = out;
        for (&w, h) in weights.iter().zip(d2h.iter()) {
            for j in (0..n).filter(|&j| !self.is_kinematic(j)) {
                for i in 0..n {
                    weighted_d2h[(i, j)] += w * h[(i, j)];
                }
            }
        }
    }

    /// The unilateral elements in row order — enforced limits, contacts with the ground and
    /// between spheres, slack strings (docs/derivations.md §13) — each a gap `φ(q) ≥ 0`, a
    /// ground contact with friction followed by its two tangent rows. Allocates: call it when
    /// setting up. A system that has any evaluates them in [`Self::gaps`].
    fn unilateral(&self) -> Vec<tree_model::Gap> {
        Vec::new()
    }

    /// `φ(q)` and `Dφ(q)` of every unilateral row ([`Self::unilateral`]) into `out.h`,
    /// `out.dh` (sized rows × dof); with `weights` (one per row) also `Σ_r w_r D²φ_r(q)` on
    /// the dynamic variables' columns into `out.weighted_d2h` — the impulses' term of the
    /// contact step's Newton matrix.
    fn gaps(&mut self, q: &Vector<Self::N>, weights: Option<&[f64]>, out: &mut ConstraintTerms) {
        let _ = (q, weights, out);
    }

    /// Evaluates the Lagrangian terms up to `order` at `(q, q̇)` into `out`, springs and the
    /// model's forces included.
    fn lagrangian(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        order: Order,
        out: &mut Terms<Self::N>,
    );

    /// The mass matrix `M(q)` into `out.mass` and `L(q, 0) = −V(q)` into `out.l` — what
    /// the Legendre transform `q̇ = M⁻¹p` and the energy of a state at `q` need. The rest of
    /// `out` is left unspecified. The default is [`Self::lagrangian`] at rest at
    /// [`Order::Dynamics`] (which allocates its zero velocity for a `Dyn` system: those
    /// override it); the interpreted system runs only the sweeps these two need.
    fn mass_matrix(&mut self, q: &Vector<Self::N>, out: &mut Terms<Self::N>) {
        let rest = self.zero_vector();
        self.lagrangian(q, &rest, Order::Dynamics, out);
    }

    /// The total energy `E = T + V` at `(q, q̇)` (springs' potentials included), also left
    /// in `out.total_energy` (the rest of `out` unspecified) — what a recorded sample
    /// reports. The default is [`Self::lagrangian`] at [`Order::First`] and its Legendre
    /// transform `q̇·∂L/∂q̇ − L`; the interpreted and compiled systems take the body
    /// velocities of the outward sweep and the first mass moments carried inward
    /// ([`tree_kernel::kernel::energy`]; no columns).
    fn energy(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        out: &mut Terms<Self::N>,
    ) -> f64 {
        self.lagrangian(q, dq, Order::First, out);
        out.total_energy = out.energy(dq);
        out.total_energy
    }

    /// `q̈` of the dynamic variables by the articulated-body algorithm, in O(frames), for a
    /// model without constraints: `tau` the generalized forces from outside the model
    /// (inputs, a caller's force) on every variable, `qdd`'s kinematic entries their
    /// prescribed accelerations. The model's own forces (springs, damping, dampers) are
    /// left in `own.force` and `own.dl_dq` (the rest of `own` unspecified). Returns `false`
    /// when the system has no such algorithm, the model has constraints, or a pivot
    /// vanishes; the caller then solves `M q̈ = …` (which names a singular variable). The
    /// default returns `false`; the interpreted system runs [`tree_kernel::articulated`], and
    /// `tree_model!` unrolls the same code for a model without constraints.
    fn articulated_acceleration(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        tau: &Vector<Self::N>,
        qdd: &mut Vector<Self::N>,
        own: &mut Terms<Self::N>,
    ) -> bool {
        let _ = (q, dq, tau, qdd, own);
        false
    }

    /// Whether [`Self::articulated_acceleration_lanes`] and [`Self::energy_lanes`] evaluate
    /// (default `false`): what a batch asks before it runs rollouts in lanes.
    fn has_lanes(&self) -> bool {
        false
    }

    /// [`Self::articulated_acceleration`] of [`WIDTH`] states at once,
    /// one per lane of [`Lanes`] (every entry of `q`, `dq`, `tau`, `qdd` one variable, the
    /// model's own forces left in `own`): each lane's `q̈` has the bits the one-state call
    /// gives, and each lane says whether its pivots held. `None` when the system has no laned
    /// evaluation (the default) or the model has constraints; the interpreted system runs
    /// [`tree_kernel::articulated`] over [`Lanes`].
    fn articulated_acceleration_lanes(
        &mut self,
        q: &[Lanes],
        dq: &[Lanes],
        tau: &[Lanes],
        qdd: &mut [Lanes],
        own: &mut ElementForces,
    ) -> Option<[bool; WIDTH]> {
        let _ = (q, dq, tau, qdd, own);
        None
    }

    /// [`Self::energy`] of [`WIDTH`] states at once, each lane's with
    /// the bits of the one-state call; `None` where [`Self::articulated_acceleration_lanes`]
    /// is.
    fn energy_lanes(&mut self, q: &[Lanes], dq: &[Lanes]) -> Option<Lanes> {
        let _ = (q, dq);
        None
    }

    /// Every frame's pose in the world, `g_sk(q)` (eq. (1)); `out.len()` must be
    /// `frame_count()`.
    fn poses(&mut self, q: &Vector<Self::N>, out: &mut [Pose]);

    /// Every Lagrangian, force and constraint output up to `order` at `(q, q̇)` over
    /// forward-mode dual numbers: each value with its exact derivative along the direction
    /// seeded in `q`, `dq` ([`Dual::seed`]) — the same evaluation as [`Self::lagrangian`] and
    /// [`Self::constraints`] together, over another scalar (generated systems compile it
    /// too). Zeroes first what it accumulates (`DualOutputs::clear_lagrangian` and
    /// `clear_constraints` at its order: outputs of a higher order keep what they held); `out`
    /// is `DualOutputs::new(dof, constraint_count)`. What the linearisations differentiate.
    fn evaluate_dual(&mut self, q: &[Dual], dq: &[Dual], order: Order, out: &mut DualOutputs);

    /// The constraint outputs of [`Self::evaluate_dual`] alone (`h`, `Dh`, and up to `order`
    /// `q̇ᵀD²h q̇` and `D²h`): what a step's second derivatives differentiate at `q₁` and
    /// `q₂`. Zeroes the constraints' outputs first (`DualOutputs::clear_constraints`); the
    /// Lagrangian's are left as they are. The default makes the whole evaluation; the
    /// interpreted and generated systems evaluate the constraints only.
    fn constraints_dual(&mut self, q: &[Dual], dq: &[Dual], order: Order, out: &mut DualOutputs) {
        self.evaluate_dual(q, dq, order, out);
    }

    /// [`Self::weighted_constraint_hessian`] over dual numbers, weights included: `h`, `Dh`
    /// and `Σ_r w_r D²h_r` on the dynamic variables' columns (`Field::WeightedD2h`, entry
    /// `(i, j)` at `i n + j`), each with its derivative along the direction seeded in `q` and
    /// `weights` — what a step's second derivatives differentiate at `q₁` (the multipliers'
    /// term `Σ_s λ_s D²h_s(q₁)` moves with `q₁` and with λ). Zeroes those outputs first
    /// (`DualOutputs::weigh`); the others are left as they are. The default evaluates the
    /// constraints at `Order::Full` ([`Self::constraints_dual`]) and sums.
    fn weighted_constraint_hessian_dual(
        &mut self,
        q: &[Dual],
        weights: &[Dual],
        out: &mut DualOutputs,
    ) {
        out.weigh(weights);
        // `q̇ᵀD²h q̇` is not an output here: any velocity will do.
        self.constraints_dual(q, q, Order::Full, out);
        let n = q.len();
        for j in (0..n).filter(|&j| !self.is_kinematic(j)) {
            for i in 0..n {
                for (r, &w) in weights.iter().enumerate() {
                    let x = out.get(Output::D2h(r, i, j));
                    out.add(Output::WeightedD2h(i, j), w * x);
                }
            }
        }
    }

    /// The inverse dynamics' terms at `(q, q̇)` and accelerations `qdd` (every variable) over
    /// [`Jet`]s ([`tree_kernel::kernel::inverse_dynamics`]: the bodies' `τ` by recursive
    /// Newton–Euler, the springs' `∂L/∂q` and `L`, the model's own forces; with constraints
    /// also their `Dh` and `q̇ᵀD²h q̇`, [`tree_kernel::kernel::constraints`]) into `out` (cleared
    /// first; `JetOutputs::new(dof, constraint_count)`): one O(frames) sweep for [`LANES`]
    /// directions, what the continuous linearisation differentiates. `false` when this system has no such evaluation (the
    /// caller differentiates [`Self::evaluate_dual`] instead).
    fn inverse_dynamics_jet(
        &mut self,
        q: &[Jet<LANES>],
        dq: &[Jet<LANES>],
        qdd: &[f64],
        out: &mut JetOutputs<LANES>,
    ) -> bool {
        let _ = (q, dq, qdd, out);
        false
    }

    /// [`Self::evaluate_dual`] at `(q, q̇)` along `(δq, δq̇)` into fresh storage (allocates).
    fn directional(
        &mut self,
        q: &[f64],
        dq: &[f64],
        dir_q: &[f64],
        dir_dq: &[f64],
        order: Order,
    ) -> DualOutputs {
        let mut out = DualOutputs::new(self.dof(), self.constraint_count());
        let (q, dq) = (Dual::seed(q, dir_q), Dual::seed(dq, dir_dq));
        self.evaluate_dual(&q, &dq, order, &mut out);
        out
    }

    /// A zero vector of the right size.
    fn zero_vector(&self) -> Vector<Self::N> {
        Vector::zeros_generic(self.dim(), U1)
    }

    /// The initial state `(q0, q̇0)` from the model.
    fn initial_state(&self) -> (Vector<Self::N>, Vector<Self::N>) {
        let mut q = self.zero_vector();
        let mut dq = self.zero_vector();
        for i in 0..self.dof() {
            (q[i], dq[i]) = self.initial(i);
        }
        (q, dq)
    }

    /// Convenience: a freshly allocated evaluation up to `order`.
    fn evaluate(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        order: Order,
    ) -> Terms<Self::N> {
        let mut t = Terms::zeros(self.dim());
        self.lagrangian(q, dq, order, &mut t);
        t
    }
}
