//! One mass's contribution to the Lagrangian and its derivatives (docs/derivations.md §2, paper
//! eqs. (15)–(18)), written once against [`FrameQuantities`] so the cached and uncached
//! modes share it.

use nalgebra::Dyn;

use crate::system::{Order, Terms};
use tree_kernel::se3::{dot, inertia_times, Pose, Twist};

/// The per-frame quantities of one massive frame k; positions `a, b` index its ancestor
/// variables (root first).
pub(crate) trait FrameQuantities {
    fn pose(&mut self) -> Pose;
    /// `v_k`.
    fn velocity(&mut self) -> Twist;
    /// `∂v_k/∂q̇_a`.
    fn jac(&mut self, a: usize) -> Twist;
    /// `∂v_k/∂q_a`.
    fn dv_dq(&mut self, a: usize) -> Twist;
    /// `∂²v_k/∂q̇_a∂q_b` (zero unless `a` is above `b`).
    fn d2v_ddq_dq(&mut self, a: usize, b: usize) -> Twist;
    /// `∂²v_k/∂q_a∂q_b`.
    fn d2v_dq_dq(&mut self, a: usize, b: usize) -> Twist;
}

/// Adds the paper's body (mass `mass` at frame k's origin, principal moments `inertia` along
/// its axes) to `out`. `vars[a]` is the global index of ancestor position `a`.
pub(crate) fn add_mass_terms(
    mass: f64,
    inertia: &[f64; 3],
    gravity: &[f64; 3],
    vars: &[usize],
    order: Order,
    fq: &mut impl FrameQuantities,
    out: &mut Terms<Dyn>,
) {
    let pose = fq.pose();
    // Gravity in body coordinates: γ·∂p_k/∂q_i = (R_kᵀγ)·(∂v_k/∂q̇_i)_lin, since ∂g_sk/∂q_i = g_sk Ĵ_i.
    let gk = pose.rotate_inverse(gravity);
    let mg = [mass * gk[0], mass * gk[1], mass * gk[2]];
    let v = fq.velocity();
    let mv = inertia_times(mass, inertia, &v);
    out.l += 0.5 * dot(&v, &mv)
        + mass * (gravity[0] * pose.p[0] + gravity[1] * pose.p[1] + gravity[2] * pose.p[2]);
    for (a, &i) in vars.iter().enumerate() {
        let ja = fq.jac(a);
        let dva = fq.dv_dq(a);
        out.dl_dq[i] += dot(&mv, &dva) + mg[0] * ja[0] + mg[1] * ja[1] + mg[2] * ja[2];
        out.dl_ddq[i] += dot(&mv, &ja);
    }
    if order < Order::Dynamics {
        return;
    }
    for (a, &i) in vars.iter().enumerate() {
        let ja = fq.jac(a);
        let m_ja = inertia_times(mass, inertia, &ja);
        for (b, &j) in vars.iter().enumerate() {
            // M_ij = Σ J_iᵀ M_k J_j (eq. (18)), one triangle mirrored.
            if b <= a {
                let mij = dot(&fq.jac(b), &m_ja);
                out.mass[(i, j)] += mij;
                if a != b {
                    out.mass[(j, i)] += mij;
                }
            }
            // ∂²L/∂q̇_i∂q_j = Σ (∂v/∂q_j)ᵀ M_k ∂v/∂q̇_i + v_kᵀ M_k ∂²v/∂q̇_i∂q_j (eq. (17)).
            let mut x = dot(&fq.dv_dq(b), &m_ja);
            if a < b {
                x += dot(&mv, &fq.d2v_ddq_dq(a, b));
            }
            out.d2l_ddq_dq[(i, j)] += x;
        }
    }
    if order < Order::Full {
        return;
    }
    for (a, &i) in vars.iter().enumerate() {
        let dva = fq.dv_dq(a);
        let m_dva = inertia_times(mass, inertia, &dva);
        let ja = fq.jac(a);
        for (b, &j) in vars.iter().enumerate().take(a + 1) {
            // ∂²L/∂q_i∂q_j = Σ (∂v/∂q_j)ᵀ M_k ∂v/∂q_i + v_kᵀ M_k ∂²v/∂q_i∂q_j + m γ·∂²p/∂q_i∂q_j,
            // with ∂²p/∂q_i∂q_j = R_k (ω_j × J_i,lin + (∂²v/∂q̇_i∂q_j)_lin).
            let jb = fq.jac(b);
            let h = if b < a { fq.d2v_ddq_dq(b, a) } else { [0.0; 6] };
            // Symmetric: with b ≤ a use the (b, a) form, ∂(J_b)/∂q_a = ∂²v/∂q̇_b∂q_a.
            let d2p = [
                ja[4] * jb[2] - ja[5] * jb[1] + h[0],
                ja[5] * jb[0] - ja[3] * jb[2] + h[1],
                ja[3] * jb[1] - ja[4] * jb[0] + h[2],
            ];
            let x = dot(&fq.dv_dq(b), &m_dva)
                + dot(&mv, &fq.d2v_dq_dq(a, b))
                + mg[0] * d2p[0]
                + mg[1] * d2p[1]
                + mg[2] * d2p[2];
            out.d2l_dq_dq[(i, j)] += x;
            if a != b {
                out.d2l_dq_dq[(j, i)] += x;
            }
        }
    }
}
