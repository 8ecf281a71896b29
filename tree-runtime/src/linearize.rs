//! The continuous linearisation: `∂q̈/∂q`, `∂q̈/∂q̇`, `∂q̈/∂u` and `∂λ/∂q`, `∂λ/∂q̇`, `∂λ/∂u` of
//! the constrained dynamics (docs/derivations.md §6), exactly: every term of the equations is
//! differentiated along each coordinate direction by the kernel over dual numbers, and the
//! differentiated KKT system
//!
//! `M_dd δq̈_d − Dh_dᵀ δλ = δF + B δu + δL_q − δ(L_q̇q) q̇ − L_q̇q δq̇ − δM q̈ + δDh_dᵀ λ`,
//! `Dh_d δq̈_d = −δDh q̈ − δ(q̇ᵀD²h q̇)`
//!
//! is solved for each direction (kinematic `q̈_k` are prescribed: they do not move). The
//! right sides along `q` come from the recursive Newton–Euler inverse dynamics and the
//! constraints over [`Jet`]s (eight directions a sweep, [`System::inverse_dynamics_jet`]);
//! along `q̇` from closed forms (`L` is quadratic in `q̇`: `∂τ/∂q̇ = Ṁ + B − Bᵀ`,
//! docs/derivations.md §9) over one second-order evaluation and one over dual numbers along
//! `q̇`. A system that offers no jets differentiates its whole evaluation over dual numbers,
//! a direction at a time. For any [`System`] (generated ones run their compiled programs);
//! without Baumgarte stabilisation.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use crate::context::StepContext;
use crate::dynamics::{Dynamics, GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::linalg::{lu_factor_packed, lu_solve_packed, lu_solve_packed_rows, mul_into, Packing};
use crate::system::{Order, Sparsity, System, Terms, Vector};
use tree_kernel::Output;
use tree_kernel::{Dual, DualOutputs, Jet, JetOutputs, LANES};

/// The accelerations and constraint forces at a state and their first derivatives. Rows: the
/// dynamic variables (`q̈`) or the constraint equations (`λ`); columns: all variables (`q`,
/// `q̇`) or the inputs (`u`).
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousDerivatives {
    /// The dynamic variables' `q̈`.
    pub qdd: DVector<f64>,
    /// The constraint forces `λ`.
    pub lambda: DVector<f64>,
    /// `∂q̈/∂q`.
    pub qdd_dq: DMatrix<f64>,
    /// `∂q̈/∂q̇`.
    pub qdd_ddq: DMatrix<f64>,
    /// `∂q̈/∂u`.
    pub qdd_du: DMatrix<f64>,
    /// `∂λ/∂q`.
    pub lambda_dq: DMatrix<f64>,
    /// `∂λ/∂q̇`.
    pub lambda_ddq: DMatrix<f64>,
    /// `∂λ/∂u`.
    pub lambda_du: DMatrix<f64>,
}

/// The linearisation of `sys`'s dynamics at `(cx.t, q, q̇)` with inputs `cx.u` (the
/// kinematic entries of `q`, `q̇` must hold their prescription at `cx.t`). Allocates its
/// workspace and result; see [`continuous_derivatives_into`].
pub fn continuous_derivatives<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
) -> Result<ContinuousDerivatives, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut ws = ContinuousWorkspace::new(&*cx.sys);
    let mut out = ContinuousDerivatives::empty();
    continuous_derivatives_into(cx, q, dq, &mut ws, &mut out)?;
    Ok(out)
}

/// The buffers of [`continuous_derivatives_into`], sized for one system.
#[derive(Clone, Debug)]
pub struct ContinuousWorkspace<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The dynamics at the state, by the mass matrix (the derivatives read `M` and
    /// `∂²L/∂q̇∂q` from its evaluation).
    dynamics: Dynamics<N>,
    qdd: Vector<N>,
    /// The KKT matrix `[[M_dd, −Dh_dᵀ], [Dh_d, 0]]`, LU-factored (column-major, packed).
    kkt: Vec<f64>,
    pivots: Vec<usize>,
    /// The state over dual numbers, and the evaluation along one direction (made on first
    /// use): along `q̇` for `Ṁ` and `D²h q̇`, or, for a system without jets, along each
    /// coordinate.
    qd: Vec<Dual>,
    vd: Vec<Dual>,
    along: Option<Box<DualOutputs>>,
    /// The second-order evaluation at the state (the forces' `∂F/∂q̇`).
    full: Terms<N>,
    /// The state over jets, and the inverse dynamics along LANES directions.
    qj: Vec<Jet<LANES>>,
    vj: Vec<Jet<LANES>>,
    jets: JetOutputs<LANES>,
    /// Every column's right side at once, row-major.
    rows: Vec<f64>,
    /// A coordinate direction, zeros, and one right-hand side.
    e: Vec<f64>,
    zero: Vec<f64>,
    b: Vec<f64>,
}

impl<N: nalgebra::Dim> ContinuousWorkspace<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// Buffers for `sys`.
    pub fn new<S: System<N = N>>(sys: &S) -> Self {
        let mut dynamics = Dynamics::new(sys);
        dynamics.articulated = false;
        let (n, k) = (
            sys.dof(),
            dynamics.split.dynamic.len() + dynamics.split.rows,
        );
        ContinuousWorkspace {
            qdd: Vector::<N>::zeros_generic(sys.dim(), nalgebra::U1),
            kkt: vec![0.0; k * k],
            pivots: vec![0; k],
            qd: vec![Dual::default(); n],
            vd: vec![Dual::default(); n],
            along: None,
            full: Terms::zeros(sys.dim()),
            qj: vec![Jet::default(); n],
            vj: vec![Jet::default(); n],
            jets: JetOutputs::new(n, sys.constraint_count()),
            rows: Vec::new(),
            e: vec![0.0; n],
            zero: vec![0.0; n],
            b: vec![0.0; k],
            dynamics,
        }
    }
}

impl ContinuousDerivatives {
    /// Empty (sized by the first [`continuous_derivatives_into`]).
    pub fn empty() -> Self {
        let z = || DMatrix::zeros(0, 0);
        ContinuousDerivatives {
            qdd: DVector::zeros(0),
            lambda: DVector::zeros(0),
            qdd_dq: z(),
            qdd_ddq: z(),
            qdd_du: z(),
            lambda_dq: z(),
            lambda_ddq: z(),
            lambda_du: z(),
        }
    }

    /// Resizes every block for `nd` dynamic variables of `n`, `m` constraint equations and
    /// `nu` inputs (only when a shape differs).
    fn fit(&mut self, nd: usize, n: usize, m: usize, nu: usize) {
        let fit = |mat: &mut DMatrix<f64>, r: usize, c: usize| {
            if mat.shape() != (r, c) {
                *mat = DMatrix::zeros(r, c);
            }
        };
        if self.qdd.len() != nd {
            self.qdd = DVector::zeros(nd);
        }
        if self.lambda.len() != m {
            self.lambda = DVector::zeros(m);
        }
        fit(&mut self.qdd_dq, nd, n);
        fit(&mut self.qdd_ddq, nd, n);
        fit(&mut self.qdd_du, nd, nu);
        fit(&mut self.lambda_dq, m, n);
        fit(&mut self.lambda_ddq, m, n);
        fit(&mut self.lambda_du, m, nu);
    }
}

/// [`continuous_derivatives`] into `out` with the buffers `ws` (made for `cx.sys`): after the
/// first call (which sizes `out`), nothing is allocated.
pub fn continuous_derivatives_into<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    ws: &mut ContinuousWorkspace<S::N>,
    out: &mut ContinuousDerivatives,
) -> Result<(), SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    factor_kkt(cx, q, dq, ws, out)?;
    let n = q.len();
    let cols = 2 * n + cx.u.len();
    let k = ws.pivots.len();
    ws.rows.resize(k * cols, 0.0);
    // The q̇ directions ride in the q sweeps' spare lanes when they all fit there (n ≤
    // LANES / 2: no sweep more); otherwise the closed forms take them.
    let swept = if 2 * n <= n.div_ceil(LANES) * LANES {
        2 * n
    } else {
        n
    };
    let mut first = 0;
    if rows_along_jets(cx, q, dq, ws, swept) {
        if swept == n {
            rows_along_velocity(cx, q, dq, ws);
        }
        solve_rows(cx, ws, out);
        first = cols;
    }
    if first < cols {
        solve_each_direction(cx, q, dq, ws, out, first);
    }
    Ok(())
}

/// `q̈` and `λ` at the state into `out`, and the KKT matrix `[[M_dd, −Dh_dᵀ], [Dh_d, 0]]`
/// factored in `ws`.
fn factor_kkt<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    ws: &mut ContinuousWorkspace<S::N>,
    out: &mut ContinuousDerivatives,
) -> Result<(), SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = q.len();
    let dynamics = &mut ws.dynamics;
    dynamics.acceleration(cx, q, dq, &mut ws.qdd)?;
    let (dynamic, m, nu) = (&dynamics.split.dynamic, dynamics.split.rows, cx.u.len());
    let (nd, k) = (dynamic.len(), dynamic.len() + m);
    out.fit(nd, n, m, nu);
    for (r, &i) in dynamic.iter().enumerate() {
        out.qdd[r] = ws.qdd[i];
    }
    out.lambda.copy_from(&dynamics.lambda);
    // Column-major.
    let mass = &dynamics.terms.mass;
    let dh = &dynamics.constraint_terms.dh;
    for c in 0..k {
        for r in 0..k {
            ws.kkt[c * k + r] = match (r < nd, c < nd) {
                (true, true) => mass[(dynamic[r], dynamic[c])],
                (true, false) => -dh[(c - nd, dynamic[r])],
                (false, true) => dh[(r - nd, dynamic[c])],
                (false, false) => 0.0,
            };
        }
    }
    lu_factor_packed(&mut ws.kkt, k, &mut ws.pivots).map_err(|_| SimError::SingularConstraints {
        step: cx.index,
        t: cx.t,
        constraint: "(the linearisation's KKT system)".into(),
    })
}

/// The right sides along `q` (and, for `swept = 2n`, along `q̇`) from the inverse dynamics
/// over jets into `ws.rows`: along a direction, the dynamic rows are `−δr + δDh_dᵀλ` for
/// the residual `r = τ(q, q̇, q̈) − ∂L_springs/∂q − F` at the solved q̈, and the constraint
/// rows `−δ(q̇ᵀD²h q̇) − δDh q̈`: one recursive Newton–Euler sweep (and one of the
/// constraints) for LANES directions at once (O(frames)), where differentiating the whole
/// evaluation forms `δM`, `δ(∂²L/∂q̇∂q)` (O(frames · depth)) and contracts them with q̈ and
/// q̇ (O(n²)) a direction. `false` when the system offers no jets.
fn rows_along_jets<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    ws: &mut ContinuousWorkspace<S::N>,
    swept: usize,
) -> bool
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = q.len();
    let (dynamic, m) = (&ws.dynamics.split.dynamic, ws.dynamics.split.rows);
    let (nd, lambda, qdd) = (dynamic.len(), &ws.dynamics.lambda, &ws.qdd);
    let cols = 2 * n + cx.u.len();
    let (qj, vj, jets, rows) = (&mut ws.qj, &mut ws.vj, &mut ws.jets, &mut ws.rows);
    for group in (0..swept).step_by(LANES) {
        for (x, &v) in qj.iter_mut().zip(q.iter()) {
            *x = Jet::constant(v);
        }
        for (x, &v) in vj.iter_mut().zip(dq.iter()) {
            *x = Jet::constant(v);
        }
        let lanes = (swept - group).min(LANES);
        for l in 0..lanes {
            let j = group + l;
            if j < n {
                qj[j].d[l] = 1.0;
            } else {
                vj[j - n].d[l] = 1.0;
            }
        }
        if !cx.sys.inverse_dynamics_jet(qj, vj, qdd.as_slice(), jets) {
            return false;
        }
        for (r, &i) in dynamic.iter().enumerate() {
            let (f, s, t) = (&jets.force[i].d, &jets.dl_dq[i].d, &jets.tau[i].d);
            let row = &mut rows[r * cols + group..r * cols + group + lanes];
            for (l, x) in row.iter_mut().enumerate() {
                *x = f[l] + s[l] - t[l];
            }
            for (c, &ls) in lambda.iter().enumerate() {
                let dh = &jets.dh[c * n + i].d;
                for (l, x) in row.iter_mut().enumerate() {
                    *x += dh[l] * ls;
                }
            }
        }
        for c in 0..m {
            let row = &mut rows[(nd + c) * cols + group..(nd + c) * cols + group + lanes];
            let curvature = &jets.dh_dot[c].d;
            for (l, x) in row.iter_mut().enumerate() {
                *x = -curvature[l];
            }
            for (j, &a) in qdd.iter().enumerate() {
                let dh = &jets.dh[c * n + j].d;
                for (l, x) in row.iter_mut().enumerate() {
                    *x -= dh[l] * a;
                }
            }
        }
    }
    true
}

/// The right sides along `q̇_j` in closed form into `ws.rows` (docs/derivations.md §9,
/// "Along q̇"): L is quadratic in q̇, so with B = ∂²L/∂q̇∂q, τ's derivative is Ṁ + B − Bᵀ
/// (Ṁ = Σ_l ∂M/∂q_l q̇_l, the Christoffel terms' 2Γq̇) and the dynamic row i is
/// `∂F_i/∂q̇_j − Ṁ_ij − B_ij + B_ji`; Dh, the springs and M do not move, and the constraint
/// row s is `−2 (D²h_s q̇)_j`. Ṁ and D²h q̇ are one evaluation over dual numbers along q̇,
/// ∂F/∂q̇ the forces' own derivatives: two evaluations for all n directions, where jets take
/// n / LANES sweeps.
fn rows_along_velocity<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    ws: &mut ContinuousWorkspace<S::N>,
) where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let n = q.len();
    let (dynamic, m) = (&ws.dynamics.split.dynamic, ws.dynamics.split.rows);
    let (nd, lvq) = (dynamic.len(), &ws.dynamics.terms.d2l_ddq_dq);
    let cols = 2 * n + cx.u.len();
    cx.sys.lagrangian(q, dq, Order::Full, &mut ws.full);
    for ((x, &v), &w) in ws.qd.iter_mut().zip(q.iter()).zip(dq.iter()) {
        *x = Dual::new(v, w);
    }
    for (x, &v) in ws.vd.iter_mut().zip(dq.iter()) {
        *x = Dual::new(v, 0.0);
    }
    let along = ws
        .along
        .get_or_insert_with(|| Box::new(DualOutputs::new(n, m)));
    cx.sys.evaluate_dual(&ws.qd, &ws.vd, Order::Dynamics, along);
    let (full, rows) = (&ws.full, &mut ws.rows);
    for (r, &i) in dynamic.iter().enumerate() {
        let row = &mut rows[r * cols + n..r * cols + 2 * n];
        for (j, x) in row.iter_mut().enumerate() {
            let force = match full.force_derivatives {
                Sparsity::Zero => 0.0,
                Sparsity::Diagonal if i != j => 0.0,
                _ => full.dforce_ddq[(i, j)],
            };
            *x = force - along.get(Output::Mass(i, j)).d - lvq[(i, j)] + lvq[(j, i)];
        }
    }
    for c in 0..m {
        let row = &mut rows[(nd + c) * cols + n..(nd + c) * cols + 2 * n];
        for (j, x) in row.iter_mut().enumerate() {
            *x = -2.0 * along.get(Output::Dh(c, j)).d;
        }
    }
}

/// The inputs' right sides (an input moves only its own row of B u), then every column
/// solved at once and scattered into `out`'s blocks.
fn solve_rows<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    ws: &mut ContinuousWorkspace<S::N>,
    out: &mut ContinuousDerivatives,
) where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (n, nu, k) = (ws.qdd.len(), cx.u.len(), ws.pivots.len());
    let dynamic = &ws.dynamics.split.dynamic;
    let (nd, cols, rows) = (dynamic.len(), 2 * n + nu, &mut ws.rows);
    for r in 0..k {
        for c in 0..nu {
            let moved = r < nd && cx.sys.input_variable(c) == dynamic[r];
            rows[r * cols + 2 * n + c] = f64::from(u8::from(moved));
        }
    }
    lu_solve_packed_rows(&ws.kkt, k, &ws.pivots, rows, cols);
    for r in 0..k {
        let row = &rows[r * cols..(r + 1) * cols];
        let (dq_block, ddq_block, du_block) = if r < nd {
            (&mut out.qdd_dq, &mut out.qdd_ddq, &mut out.qdd_du)
        } else {
            (&mut out.lambda_dq, &mut out.lambda_ddq, &mut out.lambda_du)
        };
        let i = if r < nd { r } else { r - nd };
        for j in 0..n {
            dq_block[(i, j)] = row[j];
            ddq_block[(i, j)] = row[n + j];
        }
        for c in 0..nu {
            du_block[(i, c)] = row[2 * n + c];
        }
    }
}

/// The fallback for the columns from `first` on: each direction's right side from the whole
/// evaluation over dual numbers, solved one at a time.
fn solve_each_direction<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    ws: &mut ContinuousWorkspace<S::N>,
    out: &mut ContinuousDerivatives,
    first: usize,
) where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (n, nu, k) = (q.len(), cx.u.len(), ws.pivots.len());
    let (nd, m) = (ws.dynamics.split.dynamic.len(), ws.dynamics.split.rows);
    for (x, &v) in ws.qd.iter_mut().zip(q.iter()) {
        *x = Dual::new(v, 0.0);
    }
    for (x, &v) in ws.vd.iter_mut().zip(dq.iter()) {
        *x = Dual::new(v, 0.0);
    }
    let d = ws
        .along
        .get_or_insert_with(|| Box::new(DualOutputs::new(n, m)));
    let (e, zero, b) = (&mut ws.e, &ws.zero, &mut ws.b);
    let along = Along {
        dynamics: &ws.dynamics,
        qdd: &ws.qdd,
        dq,
    };
    for j in first..(2 * n + nu) {
        if j < 2 * n {
            // Seed the one coordinate direction j.
            e.as_mut_slice().fill(0.0);
            e[j % n] = 1.0;
            let (seeded, other) = if j < n {
                (&mut ws.qd, &mut ws.vd)
            } else {
                (&mut ws.vd, &mut ws.qd)
            };
            seeded
                .iter_mut()
                .zip(e.iter())
                .for_each(|(x, &de)| x.d = de);
            other.iter_mut().for_each(|x| x.d = 0.0);
            cx.sys.evaluate_dual(&ws.qd, &ws.vd, Order::Dynamics, d);
            along.rhs(d, if j < n { zero } else { e }, None, cx.sys, b);
        } else {
            // An input moves only its own row of B u.
            d.clear();
            along.rhs(d, zero, Some(j - 2 * n), cx.sys, b);
        }
        lu_solve_packed(&ws.kkt, k, &ws.pivots, b);
        let (mut qcol, mut lcol) = match j {
            j if j < n => (out.qdd_dq.column_mut(j), out.lambda_dq.column_mut(j)),
            j if j < 2 * n => (
                out.qdd_ddq.column_mut(j - n),
                out.lambda_ddq.column_mut(j - n),
            ),
            j => (
                out.qdd_du.column_mut(j - 2 * n),
                out.lambda_du.column_mut(j - 2 * n),
            ),
        };
        qcol.copy_from_slice(&b[..nd]);
        lcol.copy_from_slice(&b[nd..]);
    }
}

/// What the right side of the differentiated equations along one direction reads: the
/// dynamics at the state, its accelerations and velocity.
struct Along<'a, N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    dynamics: &'a Dynamics<N>,
    qdd: &'a Vector<N>,
    dq: &'a Vector<N>,
}

impl<N: nalgebra::Dim> Along<'_, N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The right side along the direction `d` was evaluated on (`dir_dq` its q̇ part; `du`
    /// an input's direction) into `b`.
    fn rhs<S: System<N = N>>(
        &self,
        d: &DualOutputs,
        dir_dq: &[f64],
        du: Option<usize>,
        sys: &S,
        b: &mut [f64],
    ) {
        let (dynamic, m) = (&self.dynamics.split.dynamic, self.dynamics.split.rows);
        let (lvq, lambda) = (&self.dynamics.terms.d2l_ddq_dq, &self.dynamics.lambda);
        let (n, nd, dq, qdd) = (self.dq.len(), dynamic.len(), self.dq, self.qdd);
        for (r, &i) in dynamic.iter().enumerate() {
            let mut x = d.get(Output::Force(i)).d + d.get(Output::DlDq(i)).d;
            for j in 0..n {
                x -= d.get(Output::D2lDdqDq(i, j)).d * dq[j] + lvq[(i, j)] * dir_dq[j];
                x -= d.get(Output::Mass(i, j)).d * qdd[j];
            }
            for s in 0..m {
                x += d.get(Output::Dh(s, i)).d * lambda[s];
            }
            if let Some(k) = du {
                if sys.input_variable(k) == i {
                    x += 1.0;
                }
            }
            b[r] = x;
        }
        for s in 0..m {
            let mut x = -d.get(Output::DhDot(s)).d;
            for j in 0..n {
                x -= d.get(Output::Dh(s, j)).d * qdd[j];
            }
            b[nd + s] = x;
        }
    }
}

/// An explicit Runge–Kutta method: stage times `c`, the strictly lower-triangular stage
/// matrix `a` (row `s` uses its first `s` entries) and the weights `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tableau {
    /// Stage times, as fractions of the step.
    pub c: &'static [f64],
    /// Stage coefficients (rows padded with zeros).
    pub a: &'static [[f64; 6]],
    /// The weights of the solution the step keeps.
    pub b: &'static [f64],
}

/// The classical fourth-order Runge–Kutta method ([`crate::integrate::Rk4`]).
pub const RK4: Tableau = Tableau {
    c: &[0.0, 0.5, 0.5, 1.0],
    a: &[
        [0.0; 6],
        [0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
    ],
    b: &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
};

/// Dormand–Prince 5(4)'s fifth-order solution, the one [`crate::integrate::Rk45`] keeps (its
/// seventh, first-same-as-last stage has weight zero): an adaptive step of the length it
/// took, that length held fixed.
pub const DORMAND_PRINCE: Tableau = Tableau {
    c: &crate::integrate::rk45::C,
    a: &crate::integrate::rk45::A,
    b: &crate::integrate::rk45::B5,
};

/// One explicit step and its derivatives, on the dynamic variables' state
/// `x = (q_d, q̇_d)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ExplicitStepDerivatives {
    /// `x₂`.
    pub x2: DVector<f64>,
    /// `∂x₂/∂x₁` (2n_d × 2n_d).
    pub x2_dx1: DMatrix<f64>,
    /// `∂x₂/∂u₁` (2n_d × inputs).
    pub x2_du1: DMatrix<f64>,
}

/// One step of `tableau` of length `cx.dt` from `(cx.t, q, q̇)` and its derivatives as a map
/// on the dynamic variables' state `x = (q_d, q̇_d)`, by the chain rule through the stages:
/// with `X_s = x + Δt Σ_{r<s} a_sr K_r` and `K_s = f(X_s)`,
/// `∂K_s/∂x = A_s (I + Δt Σ_{r<s} a_sr ∂K_r/∂x)` (and for `u` with `f`'s direct term
/// `B_s`), `A_s = ∂f/∂x` at stage s from [`continuous_derivatives`], and
/// `∂x₂/∂x₁ = I + Δt Σ b_s ∂K_s/∂x` (docs/derivations.md §9). Kinematic variables follow
/// their prescription at every stage.
pub fn explicit_step_derivatives<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    tableau: &Tableau,
) -> Result<ExplicitStepDerivatives, SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let mut ws = ExplicitStepWorkspace::new(&*cx.sys);
    let mut out = ExplicitStepDerivatives::empty();
    explicit_step_derivatives_into(cx, q, dq, tableau, &mut ws, &mut out)?;
    Ok(out)
}

/// The buffers of [`explicit_step_derivatives_into`], sized for one system (the stages'
/// on the first call of a tableau).
#[derive(Clone, Debug)]
pub struct ExplicitStepWorkspace<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    continuous: ContinuousWorkspace<N>,
    derivatives: ContinuousDerivatives,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    /// Per stage: `∂K_s/∂x`, `∂K_s/∂u` and the rates `K_s = (q̇, q̈)` over all variables.
    kx: Vec<DMatrix<f64>>,
    ku: Vec<DMatrix<f64>>,
    rate_q: Vec<Vector<N>>,
    rate_v: Vec<Vector<N>>,
    /// `∂X_s/∂x`, `∂X_s/∂u` of the stage under way, its `A_s`, `B_s`.
    ix: DMatrix<f64>,
    iu: DMatrix<f64>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// The stage's point, and the step's end.
    qs: Vector<N>,
    vs: Vector<N>,
    q2: Vector<N>,
    dq2: Vector<N>,
    /// The factors of the stages' products, packed.
    packing: Packing,
}

impl<N: nalgebra::Dim> ExplicitStepWorkspace<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// Buffers for `sys`.
    pub fn new<S: System<N = N>>(sys: &S) -> Self {
        let n = sys.dof();
        let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
        let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
        let (w, nu) = (2 * dynamic.len(), sys.input_count());
        ExplicitStepWorkspace {
            continuous: ContinuousWorkspace::new(sys),
            derivatives: ContinuousDerivatives::empty(),
            dynamic,
            kinematic,
            kx: Vec::new(),
            ku: Vec::new(),
            rate_q: Vec::new(),
            rate_v: Vec::new(),
            ix: DMatrix::zeros(w, w),
            iu: DMatrix::zeros(w, nu),
            a: DMatrix::zeros(w, w),
            b: DMatrix::zeros(w, nu),
            qs: sys.zero_vector(),
            vs: sys.zero_vector(),
            q2: sys.zero_vector(),
            dq2: sys.zero_vector(),
            packing: Packing::default(),
        }
    }
}

impl ExplicitStepDerivatives {
    /// Empty (sized by the first [`explicit_step_derivatives_into`]).
    pub fn empty() -> Self {
        ExplicitStepDerivatives {
            x2: DVector::zeros(0),
            x2_dx1: DMatrix::zeros(0, 0),
            x2_du1: DMatrix::zeros(0, 0),
        }
    }
}

/// `y += a·x` over whole matrices of one shape.
fn add_scaled(y: &mut DMatrix<f64>, a: f64, x: &DMatrix<f64>) {
    for (y, x) in y.as_mut_slice().iter_mut().zip(x.as_slice()) {
        *y += a * x;
    }
}

/// [`explicit_step_derivatives`] into `out` with the buffers `ws` (made for `cx.sys`): after
/// the first call with a tableau, nothing is allocated.
pub fn explicit_step_derivatives_into<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
    tableau: &Tableau,
    ws: &mut ExplicitStepWorkspace<S::N>,
    out: &mut ExplicitStepDerivatives,
) -> Result<(), SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (nd, nu, h, t) = (ws.dynamic.len(), cx.u.len(), cx.dt, cx.t);
    let (w, stages) = (2 * nd, tableau.b.len());
    while ws.kx.len() < stages {
        ws.kx.push(DMatrix::zeros(w, w));
        ws.ku.push(DMatrix::zeros(w, nu));
        ws.rate_q.push(q.clone());
        ws.rate_v.push(q.clone());
    }
    if ws.iu.ncols() != nu {
        // The inputs given (missing ones are zero; only these have columns).
        ws.iu = DMatrix::zeros(w, nu);
        ws.b = DMatrix::zeros(w, nu);
        ws.ku.iter_mut().for_each(|k| *k = DMatrix::zeros(w, nu));
    }
    if out.x2.len() != w || out.x2_du1.ncols() != nu {
        out.x2 = DVector::zeros(w);
        out.x2_dx1 = DMatrix::zeros(w, w);
        out.x2_du1 = DMatrix::zeros(w, nu);
    }
    out.x2_dx1.fill_with_identity();
    out.x2_du1.as_mut_slice().fill(0.0);
    ws.q2.copy_from(q);
    ws.dq2.copy_from(dq);
    for s in 0..stages {
        ws.qs.copy_from(q);
        ws.vs.copy_from(dq);
        ws.ix.fill_with_identity();
        ws.iu.as_mut_slice().fill(0.0);
        for r in 0..s {
            let a = tableau.a[s][r];
            if a != 0.0 {
                ws.qs.axpy(a * h, &ws.rate_q[r], 1.0);
                ws.vs.axpy(a * h, &ws.rate_v[r], 1.0);
                add_scaled(&mut ws.ix, a * h, &ws.kx[r]);
                add_scaled(&mut ws.iu, a * h, &ws.ku[r]);
            }
        }
        let ts = t + tableau.c[s] * h;
        for &k in &ws.kinematic {
            let [x, v, _] = cx.motion.kinematic(k, ts);
            (ws.qs[k], ws.vs[k]) = (x, v);
        }
        cx.t = ts;
        let d = continuous_derivatives_into(
            cx,
            &ws.qs,
            &ws.vs,
            &mut ws.continuous,
            &mut ws.derivatives,
        );
        cx.t = t;
        d?;
        let d = &ws.derivatives;
        // A_s on the dynamic state: rows (q̇_d, q̈_d), columns (q_d, q̇_d); B_s.
        ws.a.as_mut_slice().fill(0.0);
        for r in 0..nd {
            ws.a[(r, nd + r)] = 1.0;
            for (c, &j) in ws.dynamic.iter().enumerate() {
                ws.a[(nd + r, c)] = d.qdd_dq[(r, j)];
                ws.a[(nd + r, nd + c)] = d.qdd_ddq[(r, j)];
            }
        }
        ws.b.as_mut_slice().fill(0.0);
        ws.b.view_mut((nd, 0), (nd, nu)).copy_from(&d.qdd_du);
        mul_into(&mut ws.kx[s], &ws.a, &ws.ix, 0.0, &mut ws.packing);
        ws.ku[s].copy_from(&ws.b);
        mul_into(&mut ws.ku[s], &ws.a, &ws.iu, 1.0, &mut ws.packing);
        add_scaled(&mut out.x2_dx1, tableau.b[s] * h, &ws.kx[s]);
        add_scaled(&mut out.x2_du1, tableau.b[s] * h, &ws.ku[s]);
        // This stage's rates.
        let kv = &mut ws.rate_v[s];
        kv.as_mut_slice().fill(0.0);
        for (r, &i) in ws.dynamic.iter().enumerate() {
            kv[i] = d.qdd[r];
        }
        for &k in &ws.kinematic {
            kv[k] = cx.motion.kinematic(k, ts)[2];
        }
        ws.q2.axpy(tableau.b[s] * h, &ws.vs, 1.0);
        ws.dq2.axpy(tableau.b[s] * h, kv, 1.0);
        ws.rate_q[s].copy_from(&ws.vs);
    }
    for (r, &i) in ws.dynamic.iter().enumerate() {
        out.x2[r] = ws.q2[i];
        out.x2[nd + r] = ws.dq2[i];
    }
    Ok(())
}
