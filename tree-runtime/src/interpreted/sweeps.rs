//! The default evaluation: one outward sweep (poses, body velocities, their columns
//! `∂v/∂q̇`, `∂v/∂q`; DESIGN.md §3) and one inward sweep accumulating each subtree at its
//! root — composite inertia `I^c`, momentum wrench `W`, mass and first mass moment `h` —
//! after which every entry of every derivative is O(1) (DESIGN.md §5, "sweeping the tree
//! once outward and once inward").
//!
//! For variable j driving frame f (ξ_j its axis, γ_f = R_fᵀγ gravity in f) and any variable
//! i at or above it (column a of f), with `Y = I^c ξ_j`, `Z = I^c ∂v_f/∂q_j`:
//! * `∂L/∂q̇_j = W·ξ_j`, `∂L/∂q_j = W·∂v_f/∂q_j + ξ_j·(m^c γ_f, h × γ_f)`
//! * `M_ij = J_aᵀ Y`
//! * `∂²L/∂q̇_i∂q_j = Zᵀ J_a + W·[J_a, ξ_j]` (i ≠ j), `∂²L/∂q̇_j∂q_i = (∂v_f/∂q_i)ᵀ Y`
//! * `∂²L/∂q_i∂q_j = Zᵀ ∂v_f/∂q_i + W·[∂v_f/∂q_i, ξ_j] + ξ_j·(m^c δ, h × δ)`,
//!   `δ = γ_f × ω(J_a)`
//!
//! Each is the paper's per-mass sum (eqs. (15)–(18)) with the sum over the subtree done once,
//! inward, instead of once per mass.

use nalgebra::Dyn;
use tree_model::Joint;

use super::TreeSystem;
use crate::se3::{bracket_with_axis, component, cross, dot, inertia_times, SpatialInertia};
use crate::system::{Order, Terms};

impl TreeSystem {
    pub(crate) fn evaluate_sweeps(
        &mut self,
        q: &[f64],
        dq: &[f64],
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        self.forward(q, dq, Order::First, false);
        let gravity = self.model.gravity;
        let dynamics = order >= Order::Dynamics;
        // Each frame's own contribution, then children into parents (children come later).
        for (k, f) in self.frames.iter().enumerate() {
            if !f.needed {
                continue;
            }
            self.moment[k] = [0.0; 3];
            match f.mass {
                Some(m) => {
                    let v = &self.velocity[k];
                    let p = &self.pose[k].p;
                    self.wrench[k] = inertia_times(m.mass, &m.inertia, v);
                    out.l += 0.5 * dot(v, &self.wrench[k])
                        + m.mass * (gravity[0] * p[0] + gravity[1] * p[1] + gravity[2] * p[2]);
                    if dynamics {
                        self.inertia[k] = SpatialInertia::diagonal(m.mass, &m.inertia);
                    }
                }
                None => {
                    self.wrench[k] = [0.0; 6];
                    if dynamics {
                        self.inertia[k] = SpatialInertia::default();
                    }
                }
            }
        }
        for k in (0..self.frames.len()).rev() {
            let f = &self.frames[k];
            let Some(p) = f.parent.filter(|_| f.needed) else {
                continue;
            };
            let local = &self.local[k];
            let w = local.wrench_to_parent(&self.wrench[k]);
            let h = local.moment_to_parent(&self.moment[k], self.subtree_mass[k]);
            for c in 0..3 {
                self.moment[p][c] += h[c];
            }
            for c in 0..6 {
                self.wrench[p][c] += w[c];
            }
            if dynamics {
                let i = local.inertia_to_parent(&self.inertia[k]);
                self.inertia[p].add(&i);
            }
        }
        // Per variable, then per ancestor variable: O(1) each.
        for (j, var) in self.model.variables.iter().enumerate() {
            let f = &self.frames[var.frame];
            let kind = f.kind;
            let own = f.n - 1;
            let (kc, fk) = (f.col_offset, var.frame);
            let w = self.wrench[fk];
            let h = self.moment[fk];
            let mc = self.subtree_mass[fk];
            let g = self.pose[fk].rotate_inverse(&gravity);
            let hg = cross(&h, &g);
            let gravity_wrench = [mc * g[0], mc * g[1], mc * g[2], hg[0], hg[1], hg[2]];
            let dv_own = self.dv_dq[kc + own];
            out.dl_ddq[j] = component(&w, kind);
            out.dl_dq[j] = dot(&w, &dv_own) + component(&gravity_wrench, kind);
            if !dynamics {
                continue;
            }
            let ic = &self.inertia[fk];
            let y = ic.column(kind);
            let z = ic.times(&dv_own);
            for a in 0..=own {
                let i = self.vars[f.var_start + a];
                let ja = self.jac[kc + a];
                let dva = self.dv_dq[kc + a];
                let mij = dot(&ja, &y);
                out.mass[(i, j)] = mij;
                out.mass[(j, i)] = mij;
                let mut x = dot(&z, &ja);
                if a < own {
                    x += dot(&w, &bracket_with_axis(&ja, kind));
                    out.d2l_ddq_dq[(j, i)] = dot(&dva, &y);
                }
                out.d2l_ddq_dq[(i, j)] = x;
                if order >= Order::Full {
                    let delta = cross(&g, &[ja[3], ja[4], ja[5]]);
                    let hd = cross(&h, &delta);
                    let gw = [
                        mc * delta[0],
                        mc * delta[1],
                        mc * delta[2],
                        hd[0],
                        hd[1],
                        hd[2],
                    ];
                    let x = dot(&z, &dva)
                        + dot(&w, &bracket_with_axis(&dva, kind))
                        + component(&gw, kind);
                    out.d2l_dq_dq[(i, j)] = x;
                    out.d2l_dq_dq[(j, i)] = x;
                }
            }
            debug_assert!(matches!(self.model.frames[fk].joint, Joint::Variable(v) if v == j));
        }
    }
}
