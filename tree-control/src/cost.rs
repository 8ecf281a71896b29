//! Costs: `Σ_{k<N} Δt ℓ(x_k, u_k) + ℓ_N(x_N)`, each term `½ w |r|²` with per-entry weights.
//! A [`Cost`] gives the value and, when asked, its gradient and (Gauss–Newton) Hessian.

use nalgebra::{DMatrix, DVector};

use crate::knot::{Knot, Needs};

/// `ℓ_x`, `ℓ_u`, `ℓ_xx`, `ℓ_uu`, `ℓ_ux` of one term.
#[derive(Clone, Debug, PartialEq)]
pub struct Derivatives {
    /// ℓ_x.
    pub lx: DVector<f64>,
    /// ℓ_u.
    pub lu: DVector<f64>,
    /// ℓ_xx.
    pub lxx: DMatrix<f64>,
    /// ℓ_uu.
    pub luu: DMatrix<f64>,
    /// ℓ_ux (controls × states).
    pub lux: DMatrix<f64>,
}

impl Derivatives {
    /// Zeros for `nx` states and `nu` controls.
    pub fn zeros(nx: usize, nu: usize) -> Self {
        Derivatives {
            lx: DVector::zeros(nx),
            lu: DVector::zeros(nu),
            lxx: DMatrix::zeros(nx, nx),
            luu: DMatrix::zeros(nu, nu),
            lux: DMatrix::zeros(nu, nx),
        }
    }
}

/// A cost over a horizon: user costs implement this with their derivatives. Each term is
/// written on a [`Knot`]: the state `x`, and `q`, `q̇` with their derivatives by `x`.
pub trait Cost {
    /// The running term at knot `k` (Δt included); with `d`, its derivatives (overwritten).
    fn running(&mut self, k: usize, x: &Knot, u: &DVector<f64>, d: Option<&mut Derivatives>)
        -> f64;

    /// The terminal term; with `d`, `ℓ_x` and `ℓ_xx` (the control parts zero).
    fn terminal(&mut self, x: &Knot, d: Option<&mut Derivatives>) -> f64;

    /// What the solver must compute at each knot for this cost.
    fn needs(&self) -> Needs {
        Needs::default()
    }

    /// Whether the cost fits `nx` states and `nu` controls (checked before a solve); the
    /// error is a sentence naming what does not fit.
    fn check(&self, nx: usize, nu: usize) -> Result<(), String> {
        let _ = (nx, nu);
        Ok(())
    }
}

/// `Δt Σ_k ½(x − x_ref)ᵀ W_x (x − x_ref) + ½(u − u_ref)ᵀ W_u (u − u_ref)` and
/// `½(x − x_ref)ᵀ W_N (x − x_ref)` at the end, with diagonal weights; on the VI's state
/// `x` (for example `(q_d, p_d)`) and the controls (`u_ref` for example the gravity compensation).
#[derive(Clone, Debug, PartialEq)]
pub struct QuadraticCost {
    /// The step length weighting the running terms.
    pub dt: f64,
    /// The running state reference.
    pub x_ref: DVector<f64>,
    /// Its per-entry weights.
    pub x_weight: DVector<f64>,
    /// The control reference.
    pub u_ref: DVector<f64>,
    /// Its per-entry weights.
    pub u_weight: DVector<f64>,
    /// The terminal state reference.
    pub terminal_ref: DVector<f64>,
    /// Its per-entry weights.
    pub terminal_weight: DVector<f64>,
}

/// `½ Σ w_i (a_i − b_i)²` and, with `grad`, `grad_i = s·w_i (a_i − b_i)` and `hess = s·diag(w)`.
pub(crate) fn quadratic(
    a: &DVector<f64>,
    b: &DVector<f64>,
    w: &DVector<f64>,
    s: f64,
    derivatives: Option<(&mut DVector<f64>, &mut DMatrix<f64>)>,
) -> f64 {
    let value = 0.5
        * (0..a.len())
            .map(|i| w[i] * (a[i] - b[i]).powi(2))
            .sum::<f64>();
    if let Some((grad, hess)) = derivatives {
        hess.as_mut_slice().fill(0.0);
        for i in 0..a.len() {
            grad[i] = s * w[i] * (a[i] - b[i]);
            hess[(i, i)] = s * w[i];
        }
    }
    value
}

/// The running term `Δt (½‖x − x_r‖²_{W_x} + ½‖u − u_r‖²_{W_u})` with, in `d`, its
/// derivatives (`ℓ_ux = 0`): [`QuadraticCost`]'s and a tracking MPC's.
pub(crate) fn running_quadratic(
    dt: f64,
    (x, x_ref, x_weight): (&DVector<f64>, &DVector<f64>, &DVector<f64>),
    (u, u_ref, u_weight): (&DVector<f64>, &DVector<f64>, &DVector<f64>),
    d: Option<&mut Derivatives>,
) -> f64 {
    let (lx, lu) = match d {
        Some(d) => {
            d.lux.as_mut_slice().fill(0.0);
            let Derivatives {
                lx, lu, lxx, luu, ..
            } = d;
            (Some((lx, lxx)), Some((lu, luu)))
        }
        None => (None, None),
    };
    dt * (quadratic(x, x_ref, x_weight, dt, lx) + quadratic(u, u_ref, u_weight, dt, lu))
}

/// `Ok` when each `(name, entries, wanted)` fits and every weight is finite and not
/// negative; else the sentence saying which does not (`whose`: "the cost's", say).
pub(crate) fn check_sizes_and_weights<'a>(
    whose: &str,
    sizes: &[(&str, usize, usize)],
    weights: impl Iterator<Item = &'a f64>,
) -> Result<(), String> {
    for &(name, got, want) in sizes {
        if got != want {
            return Err(format!(
                "{whose} {name} has {got} entries; the problem has {want}"
            ));
        }
    }
    match weights.copied().find(|w| !(w.is_finite() && *w >= 0.0)) {
        Some(w) => Err(format!(
            "{whose} weights must be finite and non-negative; one is {w}"
        )),
        None => Ok(()),
    }
}

impl Cost for QuadraticCost {
    fn running(
        &mut self,
        _k: usize,
        x: &Knot,
        u: &DVector<f64>,
        d: Option<&mut Derivatives>,
    ) -> f64 {
        let xs = (&x.x, &self.x_ref, &self.x_weight);
        running_quadratic(self.dt, xs, (u, &self.u_ref, &self.u_weight), d)
    }

    fn check(&self, nx: usize, nu: usize) -> Result<(), String> {
        let sizes = [
            ("x_ref", self.x_ref.len(), nx),
            ("x_weight", self.x_weight.len(), nx),
            ("u_ref", self.u_ref.len(), nu),
            ("u_weight", self.u_weight.len(), nu),
            ("terminal_ref", self.terminal_ref.len(), nx),
            ("terminal_weight", self.terminal_weight.len(), nx),
        ];
        let weights = (self.x_weight.iter())
            .chain(self.u_weight.iter())
            .chain(self.terminal_weight.iter());
        check_sizes_and_weights("the cost's", &sizes, weights)?;
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(format!(
                "the cost's dt must be positive, got {}",
                tree_model::Given(self.dt)
            ));
        }
        Ok(())
    }

    fn terminal(&mut self, x: &Knot, d: Option<&mut Derivatives>) -> f64 {
        let lx = d.map(|d| (&mut d.lx, &mut d.lxx));
        quadratic(&x.x, &self.terminal_ref, &self.terminal_weight, 1.0, lx)
    }
}
