//! Adaptive Dormand–Prince 5(4) (the tableau of Dormand & Prince 1980), with per-step error
//! control on the dynamic variables' `(q, q̇)`. The last stage of an accepted step is the
//! first of the next (first same as last: six evaluations a step); a trial step whose stages
//! are not finite is rejected and shrunk, not fatal.

use nalgebra::{allocator::Allocator, DefaultAllocator, Dim};

use crate::context::StepContext;
use crate::dynamics::{prescribe, Dynamics, GeneralizedForce, Prescription};
use crate::error::SimError;
use crate::system::{System, Vector};

pub(crate) const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
pub(crate) const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
/// Fifth-order weights (equal to the last row of `A`: first same as last).
pub(crate) const B5: [f64; 7] = [
    35.0 / 384.0,
    0.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
    0.0,
];
/// Fourth-order embedded weights.
const B4: [f64; 7] = [
    5179.0 / 57600.0,
    0.0,
    7571.0 / 16695.0,
    393.0 / 640.0,
    -92097.0 / 339200.0,
    187.0 / 2100.0,
    1.0 / 40.0,
];

/// Tolerances of the adaptive method: a component's error must stay below
/// `atol + rtol·|y|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            rtol: 1e-8,
            atol: 1e-10,
        }
    }
}

/// Dormand–Prince workspace.
#[derive(Clone, Debug)]
pub struct Rk45<N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// The error tolerance each accepted step meets.
    pub tolerance: Tolerance,
    /// The accelerations' solver (its Baumgarte setting applies).
    pub dynamics: Dynamics<N>,
    kq: [Vector<N>; 7],
    kv: [Vector<N>; 7],
    q_stage: Vector<N>,
    v_stage: Vector<N>,
    /// Steps tried and rejected so far.
    pub rejected: usize,
    /// Derivative evaluations so far.
    pub evaluations: usize,
    /// Whether stage 0 of the next step is already in `kq[0]`, `kv[0]` (at `fsal_t`).
    fsal: Option<f64>,
    /// The model forces' power `F·q̇` at each stage.
    power: [f64; 7],
    /// The energy the model's own forces took out over the last accepted step, `−∫ F·q̇ dt`
    /// by the fifth-order weights.
    pub dissipated: f64,
}

impl<N: Dim> Rk45<N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    /// An integrator with buffers sized for `sys`.
    pub fn new<S: System<N = N>>(sys: &S, tolerance: Tolerance) -> Self {
        let n = sys.dim();
        let z = || Vector::<N>::zeros_generic(n, nalgebra::U1);
        Rk45 {
            tolerance,
            evaluations: 0,
            fsal: None,
            dynamics: Dynamics::new(sys),
            kq: std::array::from_fn(|_| z()),
            kv: std::array::from_fn(|_| z()),
            q_stage: z(),
            v_stage: z(),
            rejected: 0,
            power: [0.0; 7],
            dissipated: 0.0,
        }
    }

    /// Takes one accepted step from `cx.t`, trying `cx.dt` first and shrinking it as needed
    /// but never past `t_end`. Returns the step taken; `cx.dt` becomes the proposal for the
    /// next.
    pub fn step<S, F, P>(
        &mut self,
        cx: &mut StepContext<S, F, P>,
        t_end: f64,
        q: &mut Vector<N>,
        dq: &mut Vector<N>,
    ) -> Result<f64, SimError>
    where
        S: System<N = N>,
        F: GeneralizedForce<N>,
        P: Prescription,
    {
        let (step, t) = (cx.index, cx.t);
        // Whether the last rejection was for a non-finite stage (then that is the cause to
        // report if the step shrinks to nothing).
        let mut non_finite = false;
        loop {
            let h = cx.dt.min(t_end - t);
            if h.is_nan() || h <= 1e-14 * t.abs().max(1.0) {
                if non_finite {
                    return Err(SimError::NonFinite {
                        step,
                        t,
                        what: format!("rk45 stage (at every trial step down to {h:e} s)"),
                    });
                }
                return Err(SimError::StepSizeTooSmall { step, t, dt: h });
            }
            let mut finite = true;
            for s in 0..7 {
                if s == 0 && self.fsal == Some(t) {
                    continue;
                }
                self.q_stage.copy_from(q);
                self.v_stage.copy_from(dq);
                for (r, &a) in A[s].iter().enumerate().take(s) {
                    self.q_stage.axpy(h * a, &self.kq[r], 1.0);
                    self.v_stage.axpy(h * a, &self.kv[r], 1.0);
                }
                let ts = t + C[s] * h;
                let kinematic = &self.dynamics.split.kinematic;
                prescribe(
                    kinematic,
                    cx.motion,
                    ts,
                    &mut self.q_stage,
                    &mut self.v_stage,
                    None,
                );
                self.kq[s].copy_from(&self.v_stage);
                self.evaluations += 1;
                // The stage's acceleration, at the stage's time.
                cx.t = ts;
                let stage =
                    self.dynamics
                        .acceleration(cx, &self.q_stage, &self.v_stage, &mut self.kv[s]);
                cx.t = t;
                match stage {
                    Ok(()) => self.power[s] = self.dynamics.terms.force.dot(&self.v_stage),
                    // A trial stage gone non-finite: reject the step and shrink it.
                    Err(SimError::NonFinite { .. }) if s > 0 => {
                        finite = false;
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
            // Stage 0 stays valid for a retry from the same state.
            self.fsal = Some(t);
            non_finite = !finite;
            if !finite {
                self.rejected += 1;
                cx.dt = 0.2 * h;
                continue;
            }
            // Stage 7 was evaluated at the fifth-order solution: q_stage, v_stage hold it.
            let mut err: f64 = 0.0;
            for &i in &self.dynamics.split.dynamic {
                let (mut eq, mut ev) = (0.0, 0.0);
                for s in 0..7 {
                    eq += (B5[s] - B4[s]) * self.kq[s][i];
                    ev += (B5[s] - B4[s]) * self.kv[s][i];
                }
                let tol = &self.tolerance;
                let sq = tol.atol + tol.rtol * q[i].abs().max(self.q_stage[i].abs());
                let sv = tol.atol + tol.rtol * dq[i].abs().max(self.v_stage[i].abs());
                err = err.max((h * eq).abs() / sq).max((h * ev).abs() / sv);
            }
            if !err.is_finite() {
                non_finite = true;
                self.rejected += 1;
                cx.dt = 0.2 * h;
                continue;
            }
            let factor = if err == 0.0 {
                5.0
            } else {
                (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
            };
            if err <= 1.0 {
                self.dissipated = -h * (0..7).map(|s| B5[s] * self.power[s]).sum::<f64>();
                q.copy_from(&self.q_stage);
                dq.copy_from(&self.v_stage);
                // The last stage, at (t + h, the new state), starts the next step.
                self.kq.swap(0, 6);
                self.kv.swap(0, 6);
                self.power[0] = self.power[6];
                self.fsal = Some(t + h);
                // A step shortened to land on t_end leaves the proposal as it was.
                if h >= cx.dt {
                    cx.dt *= factor;
                }
                return Ok(h);
            }
            self.rejected += 1;
            cx.dt = h * factor;
        }
    }
}
