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

/// The derivatives of one RK4 step of length `cx.dt` from `(cx.t, q, q̇)` as a map on the
/// dynamic variables' state `x = (q_d, q̇_d)`: `∂x₂/∂x₁` (2n_d × 2n_d) and `∂x₂/∂u₁`
/// (2n_d × inputs), by the chain rule through the four stages,
/// `K_s = A_s (I + c_s Δt K_{s−1})`, `A_s = ∂f/∂x` at stage s from
/// [`continuous_derivatives`], and `∂x₂/∂x₁ = I + Δt/6 Σ w_s K_s` (docs/derivations.md §9).
/// Kinematic variables follow their prescription at every stage.
pub fn rk4_step_derivatives<S, F, P>(
    cx: &mut StepContext<S, F, P>,
    q: &Vector<S::N>,
    dq: &Vector<S::N>,
) -> Result<(DMatrix<f64>, DMatrix<f64>), SimError>
where
    S: System,
    F: GeneralizedForce<S::N>,
    P: Prescription,
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    const C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
    const W: [f64; 4] = [1.0, 2.0, 2.0, 1.0];
    let n = q.len();
    let dynamic: Vec<usize> = (0..n).filter(|&i| !cx.sys.is_kinematic(i)).collect();
    let kinematic: Vec<usize> = (0..n).filter(|&i| cx.sys.is_kinematic(i)).collect();
    let (nd, nu, h, t) = (dynamic.len(), cx.u.len(), cx.dt, cx.t);
    let w = 2 * nd;
    let (mut kx, mut ku) = (DMatrix::<f64>::zeros(w, w), DMatrix::<f64>::zeros(w, nu));
    let (mut sum_x, mut sum_u) = (DMatrix::<f64>::zeros(w, w), DMatrix::<f64>::zeros(w, nu));
    // The stage's rate k = (q̇, q̈) on the dynamic rows, over all variables.
    let (mut kq, mut kv) = (cx.sys.zero_vector(), cx.sys.zero_vector());
    for s in 0..4 {
        let (mut qs, mut vs) = (q.clone(), dq.clone());
        if s > 0 {
            qs.axpy(C[s] * h, &kq, 1.0);
            vs.axpy(C[s] * h, &kv, 1.0);
        }
        let ts = t + C[s] * h;
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
        // K_s = A_s (I + c_s h K_{s−1}), and likewise for u with its direct term.
        let ix = DMatrix::<f64>::identity(w, w) + &kx * (C[s] * h);
        kx = &a * ix;
        ku = &a * (&ku * (C[s] * h)) + b;
        sum_x += &kx * (W[s] * h / 6.0);
        sum_u += &ku * (W[s] * h / 6.0);
        // This stage's rates for the next stage's state.
        kq.copy_from(&vs);
        kv.fill(0.0);
        for (r, &i) in dynamic.iter().enumerate() {
            kv[i] = d.qdd[r];
        }
        for &k in &kinematic {
            kv[k] = cx.motion.kinematic(k, ts)[2];
        }
    }
    Ok((DMatrix::<f64>::identity(w, w) + sum_x, sum_u))
}
