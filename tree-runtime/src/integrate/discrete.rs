//! The midpoint rule's discrete Lagrangian and its slot derivatives (paper eqs. (22)–(26),
//! docs/derivations.md §7), from the continuous Lagrangian's terms at its quadrature point.
//!
//! `L_d(q₁, q₂) = Δt · L(q_α, v)` with `q_α = q₁ + α(q₂ − q₁)` and `v = (q₂ − q₁)/Δt`
//! (eq. (22)). With `L_q = ∂L/∂q`, `L_q̇ = ∂L/∂q̇`, `L_qq = ∂²L/∂q²`, `L_q̇q[i][j] = ∂²L/∂q̇ᵢ∂qⱼ`
//! and `M = ∂²L/∂q̇²`, all at `(q_α, v)`:
//!
//! * `D₁L_d = (1−α)Δt L_q − L_q̇` (eq. (23)), `D₂L_d = αΔt L_q + L_q̇` (eq. (24));
//! * `D₂D₁L_d = (1−α)αΔt L_qq + (1−α) L_q̇qᵀ − α L_q̇q − M/Δt` (eq. (26)), and `D₁D₂L_d` its
//!   transpose;
//! * `D₁D₁L_d = (1−α)²Δt L_qq − (1−α)(L_q̇q + L_q̇qᵀ) + M/Δt`,
//!   `D₂D₂L_d = α²Δt L_qq + α(L_q̇q + L_q̇qᵀ) + M/Δt`.
//!
//! The VI step is built from these: its residual `p₁ + D₁L_d + …`, its Newton matrix
//! `D₂D₁L_d + …` and `p₂ = D₂L_d + …`; the step's derivatives need the others.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::system::{Terms, Vector};
use tree_kernel::Scalar;

/// Which second slot derivative of `L_d`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Slots {
    /// `D₁D₁L_d`.
    D1D1,
    /// `D₂D₁L_d` (eq. (26)); `D₁D₂L_d` is its transpose.
    D2D1,
    /// `D₂D₂L_d`.
    D2D2,
}

/// A second slot derivative of `L_d` with its coefficients `[k_qq, k_t, k_vq, k_m]` on `L_qq`,
/// `L_q̇q` transposed, `L_q̇q` and `M` (from [`DiscreteLagrangian::slot`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SecondSlot<T>([T; 4]);

impl<T: Scalar> SecondSlot<T> {
    /// Entry `(i, j)` from `L_qq[i][j]`, `L_q̇q[i][j]`, `L_q̇q[j][i]`, `M[i][j]`.
    #[inline(always)]
    pub fn at(&self, lqq_ij: T, lvq_ij: T, lvq_ji: T, m_ij: T) -> T {
        self.at_fused::<false>(lqq_ij, lvq_ij, lvq_ji, m_ij)
    }

    /// [`Self::at`], each product after the first added by a multiply-add (fused where
    /// `FUSED`: [`Scalar::multiply_add`]; unfused, the same sum in the same order).
    #[inline(always)]
    pub(crate) fn at_fused<const FUSED: bool>(
        &self,
        lqq_ij: T,
        lvq_ij: T,
        lvq_ji: T,
        m_ij: T,
    ) -> T {
        let [k_qq, k_t, k_vq, k_m] = self.0;
        let sum = k_t.multiply_add::<FUSED>(lvq_ji, k_qq * lqq_ij);
        let sum = k_vq.multiply_add::<FUSED>(lvq_ij, sum);
        k_m.multiply_add::<FUSED>(m_ij, sum)
    }
}

/// The discrete Lagrangian of one step: its quadrature point `α` and length `Δt`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiscreteLagrangian {
    /// Quadrature point `α ∈ [0, 1]`.
    pub alpha: f64,
    /// Step length `Δt`.
    pub dt: f64,
}

impl DiscreteLagrangian {
    /// Where `L` is evaluated: `q_α = q₁ + α(q₂ − q₁)` and `v = (q₂ − q₁)/Δt` (eq. (22)).
    pub fn point<N: Dim>(
        &self,
        q1: &Vector<N>,
        q2: &Vector<N>,
        q_alpha: &mut Vector<N>,
        v: &mut Vector<N>,
    ) where
        DefaultAllocator: Allocator<N>,
    {
        v.copy_from(q2);
        *v -= q1;
        *v /= self.dt;
        q_alpha.copy_from(q1);
        q_alpha.axpy(self.alpha * self.dt, v, 1.0);
    }

    /// `(D₁L_d)ᵢ = (1−α)Δt ∂L/∂qᵢ − ∂L/∂q̇ᵢ` (eq. (23)) from the terms at the point.
    #[inline]
    pub fn d1<N: Dim>(&self, t: &Terms<N>, i: usize) -> f64
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        (1.0 - self.alpha) * self.dt * t.dl_dq[i] - t.dl_ddq[i]
    }

    /// `(1−α)Δt |∂L/∂qᵢ| + |∂L/∂q̇ᵢ|`: the size of `(D₁L_d)ᵢ`'s two terms before they
    /// cancel (a residual row's momentum scale, docs/derivations.md §7).
    #[inline]
    pub(crate) fn d1_scale<N: Dim>(&self, t: &Terms<N>, i: usize) -> f64
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        (1.0 - self.alpha) * self.dt * t.dl_dq[i].abs() + t.dl_ddq[i].abs()
    }

    /// `(D₂L_d)ᵢ = αΔt ∂L/∂qᵢ + ∂L/∂q̇ᵢ` (eq. (24)): the momentum the step ends with.
    #[inline]
    pub fn d2<N: Dim>(&self, t: &Terms<N>, i: usize) -> f64
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        self.alpha * self.dt * t.dl_dq[i] + t.dl_ddq[i]
    }

    /// The coefficients `(k_qq, k_t, k_vq, k_m)` of one second slot derivative: entry
    /// `(i, j) = k_qq L_qq[i][j] + k_t L_q̇q[j][i] + k_vq L_q̇q[i][j] + k_m M[i][j]` (the
    /// formulas of the module docs).
    fn coefficients(&self, slots: Slots) -> [f64; 4] {
        let (a, dt) = (self.alpha, self.dt);
        let b = 1.0 - a;
        match slots {
            Slots::D1D1 => [b * b * dt, -b, -b, 1.0 / dt],
            Slots::D2D1 => [b * a * dt, b, -a, -1.0 / dt],
            Slots::D2D2 => [a * a * dt, a, a, 1.0 / dt],
        }
    }

    /// The second slot derivative `slots` with its coefficients worked out once, for filling
    /// many entries: entry `(i, j)` from the continuous terms' entries `L_qq[i][j]`,
    /// `L_q̇q[i][j]`, `L_q̇q[j][i]`, `M[i][j]` ([`SecondSlot::at`]), over any scalar.
    pub(crate) fn slot<T: Scalar>(&self, slots: Slots) -> SecondSlot<T> {
        SecondSlot(self.coefficients(slots).map(T::constant))
    }

    /// Fills `out` (column-major, n × n) with `D₂D₁L_d`: entry `(i, j) = ∂(D₁L_d)ᵢ/∂q₂ⱼ`
    /// (eq. (26)). Needs the terms at `Order::Full`.
    pub fn d2d1<N: Dim>(&self, t: &Terms<N>, out: &mut [f64])
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        self.fill(Slots::D2D1, t, out);
    }

    /// Fills `out` with `D₁D₁L_d`: entry `(i, j) = ∂(D₁L_d)ᵢ/∂q₁ⱼ`.
    pub fn d1d1<N: Dim>(&self, t: &Terms<N>, out: &mut [f64])
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        self.fill(Slots::D1D1, t, out);
    }

    /// Fills `out` with `D₂D₂L_d`: entry `(i, j) = ∂(D₂L_d)ᵢ/∂q₂ⱼ`.
    pub fn d2d2<N: Dim>(&self, t: &Terms<N>, out: &mut [f64])
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        self.fill(Slots::D2D2, t, out);
    }

    /// Fills `out` (column-major) with the second slot derivative `slots`.
    #[inline]
    fn fill<N: Dim>(&self, slots: Slots, t: &Terms<N>, out: &mut [f64])
    where
        DefaultAllocator: Allocator<N> + Allocator<N, N>,
    {
        let n = t.dl_dq.len();
        let (lqq, lvq, mass) = (
            t.d2l_dq_dq.as_slice(),
            t.d2l_ddq_dq.as_slice(),
            t.mass.as_slice(),
        );
        let slot = self.slot::<f64>(slots);
        // Column-major: entry (i, j) at j·n + i.
        for j in 0..n {
            for i in 0..n {
                let ij = j * n + i;
                out[ij] = slot.at(lqq[ij], lvq[ij], lvq[i * n + j], mass[ij]);
            }
        }
    }
}
