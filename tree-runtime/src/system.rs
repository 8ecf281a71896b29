//! The one trait every simulated system implements — the interpreted tree and the code
//! `tree_model!` generates — and the Lagrangian terms it yields.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim, OMatrix, OVector, U1};

pub use crate::order::Order;
use crate::se3::Pose;
use crate::sweeps::TermsSink;

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
    /// `L = Σ_k ½ v_kᵀ M_k v_k + m_k γ·p_k` (eq. (15), gravity sign as in DESIGN.md §3).
    pub l: f64,
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
}

impl<N: Dim> Terms<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// All zeros, sized for `n`.
    pub fn zeros(n: N) -> Self {
        Terms {
            l: 0.0,
            dl_dq: Vector::zeros_generic(n, U1),
            dl_ddq: Vector::zeros_generic(n, U1),
            mass: Matrix::zeros_generic(n, n),
            d2l_ddq_dq: Matrix::zeros_generic(n, n),
            d2l_dq_dq: Matrix::zeros_generic(n, n),
        }
    }

    /// Zeroes what `order` asks for, ready to accumulate.
    pub fn clear(&mut self, order: Order) {
        self.l = 0.0;
        self.dl_dq.fill(0.0);
        self.dl_ddq.fill(0.0);
        if order >= Order::Dynamics {
            self.mass.fill(0.0);
            self.d2l_ddq_dq.fill(0.0);
        }
        if order >= Order::Full {
            self.d2l_dq_dq.fill(0.0);
        }
    }

    /// Total energy `E = q̇·∂L/∂q̇ − L` (the Legendre transform; `T + V` here).
    pub fn energy(&self, dq: &Vector<N>) -> f64 {
        self.dl_ddq.dot(dq) - self.l
    }
}

impl<N: Dim> TermsSink<f64> for Terms<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    fn set_l(&mut self, l: f64) {
        self.l = l;
    }
    fn set_dl_dq(&mut self, i: usize, x: f64) {
        self.dl_dq[i] = x;
    }
    fn set_dl_ddq(&mut self, i: usize, x: f64) {
        self.dl_ddq[i] = x;
    }
    fn set_mass(&mut self, i: usize, j: usize, x: f64) {
        self.mass[(i, j)] = x;
    }
    fn set_d2l_ddq_dq(&mut self, i: usize, j: usize, x: f64) {
        self.d2l_ddq_dq[(i, j)] = x;
    }
    fn set_d2l_dq_dq(&mut self, i: usize, j: usize, x: f64) {
        self.d2l_dq_dq[(i, j)] = x;
    }
}

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

    /// The viscous damping coefficient `c_i` (generalized force `−c_i q̇_i`).
    fn damping(&self, i: usize) -> f64;

    /// Evaluates the Lagrangian terms up to `order` at `(q, q̇)` into `out`.
    fn lagrangian(
        &mut self,
        q: &Vector<Self::N>,
        dq: &Vector<Self::N>,
        order: Order,
        out: &mut Terms<Self::N>,
    );

    /// Every frame's pose in the world, `g_sk(q)` (eq. (1)); `out.len()` must be
    /// `frame_count()`.
    fn poses(&mut self, q: &Vector<Self::N>, out: &mut [Pose]);

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
