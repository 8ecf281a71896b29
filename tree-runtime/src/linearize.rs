//! The continuous linearisation: `∂q̈/∂q`, `∂q̈/∂q̇`, `∂q̈/∂u` and `∂λ/∂q`, `∂λ/∂q̇`, `∂λ/∂u` of
//! the constrained dynamics (docs/derivations.md §6), exactly: every term of the equations is
//! differentiated along each coordinate direction by the kernel over dual numbers, and the
//! differentiated KKT system
//!
//! `M_dd δq̈_d − Dh_dᵀ δλ = δF + B δu + δL_q − δ(L_q̇q) q̇ − L_q̇q δq̇ − δM q̈ + δDh_dᵀ λ`,
//! `Dh_d δq̈_d = −δDh q̈ − δ(q̇ᵀD²h q̇)`
//!
//! is solved for each direction (kinematic `q̈_k` are prescribed: they do not move). For any
//! [`System`] (generated ones evaluate their compiled dual program); without Baumgarte
//! stabilisation.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use crate::context::StepContext;
use crate::dual::{Dual, DualOutputs};
use crate::dynamics::{Dynamics, GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::outputs::Output;
use crate::system::{Order, System, Vector};

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
/// kinematic entries of `q`, `q̇` must hold their prescription at `cx.t`).
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
    let n = q.len();
    let mut dynamics = Dynamics::new(&*cx.sys);
    // The derivatives read M and ∂²L/∂q̇∂q from the evaluation.
    dynamics.articulated = false;
    let mut qdd = Vector::<S::N>::zeros_generic(cx.sys.dim(), nalgebra::U1);
    dynamics.acceleration(cx, q, dq, &mut qdd)?;
    let lambda = dynamics.lambda.clone();
    let (dynamic, m, nu) = (
        dynamics.split.dynamic.clone(),
        dynamics.split.rows,
        cx.u.len(),
    );
    let nd = dynamic.len();
    // The KKT matrix [[M_dd, −Dh_dᵀ], [Dh_d, 0]] at the state.
    let mass = &dynamics.terms.mass;
    let dh = &dynamics.constraint_terms.dh;
    let kkt = DMatrix::from_fn(nd + m, nd + m, |r, c| match (r < nd, c < nd) {
        (true, true) => mass[(dynamic[r], dynamic[c])],
        (true, false) => -dh[(c - nd, dynamic[r])],
        (false, true) => dh[(r - nd, dynamic[c])],
        (false, false) => 0.0,
    });
    let lu = kkt.lu();
    let lvq = &dynamics.terms.d2l_ddq_dq;
    // The right side of the differentiated equations along one direction.
    let rhs_along = |d: &DualOutputs, dir_dq: &[f64], du: Option<usize>, sys: &S| {
        let mut b = DVector::<f64>::zeros(nd + m);
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
        b
    };
    let mut out = ContinuousDerivatives {
        qdd: DVector::from_iterator(nd, dynamic.iter().map(|&i| qdd[i])),
        lambda: lambda.clone(),
        qdd_dq: DMatrix::zeros(nd, n),
        qdd_ddq: DMatrix::zeros(nd, n),
        qdd_du: DMatrix::zeros(nd, nu),
        lambda_dq: DMatrix::zeros(m, n),
        lambda_ddq: DMatrix::zeros(m, n),
        lambda_du: DMatrix::zeros(m, nu),
    };
    let singular = || SimError::SingularConstraints {
        step: cx.index,
        t: cx.t,
        constraint: "(the linearisation's KKT system)".into(),
    };
    let zero = vec![0.0; n];
    let (mut qd, mut vd) = (
        Dual::seed(q.as_slice(), &zero),
        Dual::seed(dq.as_slice(), &zero),
    );
    let mut d = DualOutputs::new(n, m);
    let mut e = vec![0.0; n];
    for j in 0..(2 * n + nu) {
        let b = if j < 2 * n {
            // Seed the one coordinate direction j.
            e.fill(0.0);
            e[j % n] = 1.0;
            let (seeded, other) = if j < n {
                (&mut qd, &mut vd)
            } else {
                (&mut vd, &mut qd)
            };
            seeded.iter_mut().zip(&e).for_each(|(x, &de)| x.d = de);
            other.iter_mut().for_each(|x| x.d = 0.0);
            cx.sys.evaluate_dual(&qd, &vd, Order::Dynamics, &mut d);
            rhs_along(&d, if j < n { &zero } else { &e }, None, cx.sys)
        } else {
            // An input moves only its own row of B u.
            d.clear();
            rhs_along(&d, &zero, Some(j - 2 * n), cx.sys)
        };
        let x = lu.solve(&b).ok_or_else(singular)?;
        let (qcol, lcol) = (x.rows(0, nd), x.rows(nd, m));
        match j {
            j if j < n => {
                out.qdd_dq.set_column(j, &qcol);
                out.lambda_dq.set_column(j, &lcol);
            }
            j if j < 2 * n => {
                out.qdd_ddq.set_column(j - n, &qcol);
                out.lambda_ddq.set_column(j - n, &lcol);
            }
            j => {
                out.qdd_du.set_column(j - 2 * n, &qcol);
                out.lambda_du.set_column(j - 2 * n, &lcol);
            }
        }
    }
    Ok(out)
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
    let n = q.len();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !cx.sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| cx.sys.is_kinematic(i)).collect();
    let (nd, nu, h, t) = (dynamic.len(), cx.u.len(), cx.dt, cx.t);
    let (w, stages) = (2 * nd, tableau.b.len());
    // Per stage: ∂K_s/∂x, ∂K_s/∂u and the rates K_s = (q̇, q̈) over all variables.
    let mut kx: Vec<DMatrix<f64>> = Vec::with_capacity(stages);
    let mut ku: Vec<DMatrix<f64>> = Vec::with_capacity(stages);
    let mut rate_q: Vec<Vector<S::N>> = Vec::with_capacity(stages);
    let mut rate_v: Vec<Vector<S::N>> = Vec::with_capacity(stages);
    let (mut x2_dx1, mut x2_du1) = (DMatrix::<f64>::identity(w, w), DMatrix::<f64>::zeros(w, nu));
    let (mut q2, mut dq2) = (q.clone(), dq.clone());
    for s in 0..stages {
        let (mut qs, mut vs) = (q.clone(), dq.clone());
        let (mut ix, mut iu) = (DMatrix::<f64>::identity(w, w), DMatrix::<f64>::zeros(w, nu));
        for r in 0..s {
            let a = tableau.a[s][r];
            if a != 0.0 {
                qs.axpy(a * h, &rate_q[r], 1.0);
                vs.axpy(a * h, &rate_v[r], 1.0);
                ix += &kx[r] * (a * h);
                iu += &ku[r] * (a * h);
            }
        }
        let ts = t + tableau.c[s] * h;
        for &k in &kinematic {
            let [x, v, _] = cx.motion.kinematic(k, ts);
            (qs[k], vs[k]) = (x, v);
        }
        cx.t = ts;
        let d = continuous_derivatives(cx, &qs, &vs);
        cx.t = t;
        let d = d?;
        // A_s on the dynamic state: rows (q̇_d, q̈_d), columns (q_d, q̇_d).
        let mut a = DMatrix::<f64>::zeros(w, w);
        for r in 0..nd {
            a[(r, nd + r)] = 1.0;
            for (c, &j) in dynamic.iter().enumerate() {
                a[(nd + r, c)] = d.qdd_dq[(r, j)];
                a[(nd + r, nd + c)] = d.qdd_ddq[(r, j)];
            }
        }
        let mut b = DMatrix::<f64>::zeros(w, nu);
        b.view_mut((nd, 0), (nd, nu)).copy_from(&d.qdd_du);
        kx.push(&a * ix);
        ku.push(&a * iu + b);
        x2_dx1 += &kx[s] * (tableau.b[s] * h);
        x2_du1 += &ku[s] * (tableau.b[s] * h);
        // This stage's rates.
        let mut kv = cx.sys.zero_vector();
        for (r, &i) in dynamic.iter().enumerate() {
            kv[i] = d.qdd[r];
        }
        for &k in &kinematic {
            kv[k] = cx.motion.kinematic(k, ts)[2];
        }
        q2.axpy(tableau.b[s] * h, &vs, 1.0);
        dq2.axpy(tableau.b[s] * h, &kv, 1.0);
        rate_q.push(vs);
        rate_v.push(kv);
    }
    let x2 = DVector::from_iterator(
        w,
        dynamic
            .iter()
            .map(|&i| q2[i])
            .chain(dynamic.iter().map(|&i| dq2[i])),
    );
    Ok(ExplicitStepDerivatives { x2, x2_dx1, x2_du1 })
}
