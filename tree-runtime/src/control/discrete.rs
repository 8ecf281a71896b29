//! A system discretised in time as a control system `x_{k+1} = f_k(x_k, u_k)`, by the
//! midpoint VI (default) or RK4 (docs/derivations.md §10).
//!
//! The state is `x = (q_d, v_d, m)`: the dynamic variables' configuration, their momentum
//! `p_d` (VI) or velocity `q̇_d` (RK4), and a memory `m` of the controls — for each input
//! its previous value (what a `control_rate` term differences against), for each kinematic
//! control its value and velocity `(ρ_k − ρ_{k−1})/Δt` at the knot (trep's `(q_k, v_k)`).
//! The controls `u_k` are the chosen inputs, held over step k, and the chosen kinematic
//! variables' values at knot `k + 1` (trep's ρ), linear in time over the step; every other
//! input is zero and every other kinematic variable follows its prescription.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use super::cost::Needs;
use crate::context::StepContext;
use crate::dynamics::{ModelMotions, NoForce, Prescription};
use crate::error::SimError;
use crate::integrate::{MidpointVi, Rk4, StepCovector, StepDerivatives, ViSettings};
use crate::linearize::{explicit_step_derivatives, RK4};
use crate::system::{Order, System, Terms, Vector};
use tree_model::Control;

/// The discretisation.
enum Method<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    Vi(Box<MidpointVi<N>>),
    Rk4(Box<Rk4<N>>),
}

/// The configuration, velocity and their derivatives by the state at a knot: what costs
/// are written on.
#[derive(Clone, Debug, PartialEq)]
pub struct Knot {
    /// The state.
    pub x: DVector<f64>,
    /// Every variable's value.
    pub q: DVector<f64>,
    /// Every variable's velocity (for the VI, the one consistent with the momentum).
    pub dq: DVector<f64>,
    /// `∂q/∂x` (n × states).
    pub q_x: DMatrix<f64>,
    /// `∂q̇/∂x` (n × states).
    pub dq_x: DMatrix<f64>,
    /// Per control: the input that holds `q` at rest, `g(q) = −∂L/∂q` at `q̇ = 0` on its
    /// variable (zero for kinematic controls).
    pub gravity: DVector<f64>,
    /// `∂g/∂x` (controls × states).
    pub gravity_x: DMatrix<f64>,
    /// Per control: its previous value (the memory part of `x`).
    pub previous: DVector<f64>,
    /// Where each control's previous value sits in `x`.
    pub previous_at: Vec<usize>,
}

/// The system as `x_{k+1} = f_k(x_k, u_k)`, with its buffers (nothing allocated per step
/// after the first Jacobian).
pub struct DiscreteSystem<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// The system.
    pub sys: S,
    method: Method<S::N>,
    motion: ModelMotions,
    /// The step length.
    pub dt: f64,
    /// The time of knot 0.
    pub t0: f64,
    controls: Vec<Control>,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    /// Per control, its memory's first slot in `x`.
    memory: Vec<usize>,
    inputs: Vec<f64>,
    q1: Vector<S::N>,
    p1: Vector<S::N>,
    q2: Vector<S::N>,
    p2: Vector<S::N>,
    next: Vector<S::N>,
    first: StepDerivatives,
    hessian: DMatrix<f64>,
    covector: StepCovector,
    terms: Terms<S::N>,
}

/// The kinematic variables' motion over a step: the controlled ones linear from their knot
/// value to their decision, the rest on the model's prescription.
struct Decided<'a> {
    model: &'a mut ModelMotions,
    /// `(variable, value at t₁, value at t₁ + Δt)`.
    controlled: &'a [(usize, f64, f64)],
    t1: f64,
    dt: f64,
}

impl Prescription for Decided<'_> {
    fn kinematic(&mut self, i: usize, t: f64) -> [f64; 3] {
        match self.controlled.iter().find(|c| c.0 == i) {
            Some(&(_, a, b)) => {
                let v = (b - a) / self.dt;
                [a + v * (t - self.t1), v, 0.0]
            }
            None => self.model.kinematic(i, t),
        }
    }
}

impl<S: System> DiscreteSystem<S>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// The VI of `sys` at step `dt` from time `t0`, every input a control.
    pub fn new(sys: S, settings: ViSettings, dt: f64, t0: f64) -> Self {
        let controls = (0..sys.input_count()).map(Control::Input).collect();
        Self::vi(sys, settings, dt, t0, controls).expect("every input is a valid control")
    }

    /// The VI with the given controls (inputs and kinematic variables).
    pub fn vi(
        sys: S,
        settings: ViSettings,
        dt: f64,
        t0: f64,
        controls: Vec<Control>,
    ) -> Result<Self, SimError> {
        let vi = MidpointVi::new(&sys, settings);
        Self::build(sys, Method::Vi(Box::new(vi)), dt, t0, controls)
    }

    /// RK4 on `(q_d, q̇_d)` with the given controls (inputs only: a kinematic variable would
    /// need its velocity and acceleration between knots).
    pub fn rk4(sys: S, dt: f64, t0: f64, controls: Vec<Control>) -> Result<Self, SimError> {
        if let Some(Control::Kinematic(i)) =
            controls.iter().find(|c| matches!(c, Control::Kinematic(_)))
        {
            return Err(SimError::InvalidInput(format!(
                "kinematic control `{}` needs the VI: RK4 would need its velocity and acceleration between knots",
                sys.variable_name(*i)
            )));
        }
        let rk4 = Rk4::new(&sys);
        Self::build(sys, Method::Rk4(Box::new(rk4)), dt, t0, controls)
    }

    fn build(
        sys: S,
        method: Method<S::N>,
        dt: f64,
        t0: f64,
        controls: Vec<Control>,
    ) -> Result<Self, SimError> {
        if !(dt.is_finite() && dt > 0.0 && t0.is_finite()) {
            return Err(SimError::InvalidInput(format!(
                "the step must be positive and the start time finite, got dt = {dt}, t0 = {t0}"
            )));
        }
        let n = sys.dof();
        for c in &controls {
            let bad = match *c {
                Control::Input(k) => (k >= sys.input_count()).then(|| format!("input {k}")),
                Control::Kinematic(i) => (i >= n || !sys.is_kinematic(i))
                    .then(|| format!("variable {i} (not kinematic)")),
            };
            if let Some(what) = bad {
                return Err(SimError::InvalidInput(format!(
                    "control {what} is not a control of this system"
                )));
            }
        }
        let dynamic: Vec<usize> = (0..n).filter(|&i| !sys.is_kinematic(i)).collect();
        let kinematic: Vec<usize> = (0..n).filter(|&i| sys.is_kinematic(i)).collect();
        let nd = dynamic.len();
        let mut memory = Vec::with_capacity(controls.len());
        let mut at = 2 * nd;
        for c in &controls {
            memory.push(at);
            at += match c {
                Control::Input(_) => 1,
                Control::Kinematic(_) => 2,
            };
        }
        let z = sys.zero_vector();
        Ok(DiscreteSystem {
            motion: ModelMotions::of(&sys),
            covector: StepCovector {
                q2: DVector::zeros(nd),
                p2: DVector::zeros(nd),
                lambda: DVector::zeros(sys.constraint_count()),
            },
            inputs: vec![0.0; sys.input_count()],
            terms: Terms::zeros(sys.dim()),
            method,
            dt,
            t0,
            controls,
            dynamic,
            kinematic,
            memory,
            q1: z.clone(),
            p1: z.clone(),
            q2: z.clone(),
            p2: z.clone(),
            next: z,
            first: StepDerivatives::empty(),
            hessian: DMatrix::zeros(0, 0),
            sys,
        })
    }

    /// The state's size: `2 n_d` plus the controls' memory.
    pub fn states(&self) -> usize {
        2 * self.dynamic.len()
            + self
                .controls
                .iter()
                .map(|c| match c {
                    Control::Input(_) => 1,
                    Control::Kinematic(_) => 2,
                })
                .sum::<usize>()
    }

    /// The number of controls.
    pub fn controls(&self) -> usize {
        self.controls.len()
    }

    /// The controls, in order.
    pub fn control_list(&self) -> &[Control] {
        &self.controls
    }

    /// Whether this is the VI (otherwise RK4).
    pub fn is_vi(&self) -> bool {
        matches!(self.method, Method::Vi(_))
    }

    /// The VI's settings, when it is the VI.
    pub fn vi_settings(&self) -> Option<&ViSettings> {
        match &self.method {
            Method::Vi(vi) => Some(&vi.settings),
            Method::Rk4(_) => None,
        }
    }

    /// The constraint multipliers of the last step (VI: `λ` of the step; RK4: none).
    pub fn multipliers(&self) -> &[f64] {
        match &self.method {
            Method::Vi(vi) => vi.lambda.as_slice(),
            Method::Rk4(_) => &[],
        }
    }

    /// The state of `(q, q̇)` at knot 0, the controls' memory from `previous` (their values
    /// "before" the start: the initial guess of inputs, the start value of kinematic ones,
    /// at rest).
    pub fn state_of(
        &mut self,
        q: &Vector<S::N>,
        dq: &Vector<S::N>,
        previous: &[f64],
    ) -> DVector<f64> {
        let nd = self.dynamic.len();
        let mut x = DVector::zeros(self.states());
        let v = match &mut self.method {
            Method::Vi(vi) => vi.initial_momentum(&mut self.sys, q, dq),
            Method::Rk4(_) => dq.clone(),
        };
        for (r, &i) in self.dynamic.iter().enumerate() {
            x[r] = q[i];
            x[nd + r] = v[i];
        }
        for (c, control) in self.controls.iter().enumerate() {
            match *control {
                Control::Input(_) => x[self.memory[c]] = previous.get(c).copied().unwrap_or(0.0),
                Control::Kinematic(i) => {
                    x[self.memory[c]] = q[i];
                    x[self.memory[c] + 1] = dq[i];
                }
            }
        }
        x
    }

    /// The configuration at knot `k` of state `x` (controlled kinematic variables from the
    /// memory, the others on their prescription) into `q`, and their velocities into `dq`'s
    /// kinematic entries.
    fn place(&mut self, k: usize, x: &[f64], q: &mut Vector<S::N>, dq: Option<&mut Vector<S::N>>) {
        let t = self.t0 + k as f64 * self.dt;
        for (r, &i) in self.dynamic.iter().enumerate() {
            q[i] = x[r];
        }
        let mut dq = dq;
        for &i in &self.kinematic {
            let [v, d, _] = self.motion.kinematic(i, t);
            q[i] = v;
            if let Some(dq) = dq.as_mut() {
                dq[i] = d;
            }
        }
        for (c, control) in self.controls.iter().enumerate() {
            if let Control::Kinematic(i) = *control {
                q[i] = x[self.memory[c]];
                if let Some(dq) = dq.as_mut() {
                    dq[i] = x[self.memory[c] + 1];
                }
            }
        }
    }

    /// The configuration at knot `k` of state `x`.
    pub fn configuration(&mut self, k: usize, x: &[f64], q: &mut Vector<S::N>) {
        self.place(k, x, q, None);
    }

    /// The inputs that hold configuration `q` at rest against gravity and springs, per
    /// control (`u = −∂L/∂q` at `q̇ = 0` on each input's variable; zero for kinematic
    /// controls).
    pub fn gravity_compensation(&mut self, q: &Vector<S::N>) -> DVector<f64> {
        let zero = self.sys.zero_vector();
        self.sys.lagrangian(q, &zero, Order::First, &mut self.terms);
        DVector::from_fn(self.controls.len(), |c, _| match self.controls[c] {
            Control::Input(k) => -self.terms.dl_dq[self.sys.input_variable(k)],
            Control::Kinematic(_) => 0.0,
        })
    }

    /// What costs see at knot `k` of state `x` (with `derivatives`, also the Jacobians);
    /// `needs` says whether the VI's velocity (a solve) and the gravity compensation are
    /// computed (otherwise the dynamic velocities and the gravity are left zero).
    pub fn knot(
        &mut self,
        k: usize,
        x: &[f64],
        out: &mut Knot,
        derivatives: bool,
        needs: Needs,
    ) -> Result<(), SimError> {
        let gravity = needs.gravity;
        let (n, nx, nu, nd) = (
            self.sys.dof(),
            self.states(),
            self.controls(),
            self.dynamic.len(),
        );
        if out.q.len() != n || out.x.len() != nx || out.gravity.len() != nu {
            *out = Knot {
                x: DVector::zeros(nx),
                q: DVector::zeros(n),
                dq: DVector::zeros(n),
                q_x: DMatrix::zeros(n, nx),
                dq_x: DMatrix::zeros(n, nx),
                gravity: DVector::zeros(nu),
                gravity_x: DMatrix::zeros(nu, nx),
                previous: DVector::zeros(nu),
                previous_at: self.memory.clone(),
            };
        }
        out.x.as_mut_slice().copy_from_slice(x);
        let (mut q, mut dq) = (self.sys.zero_vector(), self.sys.zero_vector());
        self.place(k, x, &mut q, Some(&mut dq));
        for c in 0..nu {
            out.previous[c] = x[self.memory[c]];
        }
        if derivatives {
            out.q_x.fill(0.0);
            out.dq_x.fill(0.0);
            for (r, &i) in self.dynamic.iter().enumerate() {
                out.q_x[(i, r)] = 1.0;
            }
            for (c, control) in self.controls.iter().enumerate() {
                if let Control::Kinematic(i) = *control {
                    out.q_x[(i, self.memory[c])] = 1.0;
                    out.dq_x[(i, self.memory[c] + 1)] = 1.0;
                }
            }
        }
        match self.method {
            Method::Rk4(_) => {
                for (r, &i) in self.dynamic.iter().enumerate() {
                    dq[i] = x[nd + r];
                    if derivatives {
                        out.dq_x[(i, nd + r)] = 1.0;
                    }
                }
            }
            Method::Vi(_) if !needs.velocity => {}
            Method::Vi(_) => {
                // q̇_d = M_dd⁻¹ (p_d − M_dk q̇_k): L is quadratic in q̇, so p = M q̇.
                self.sys
                    .lagrangian(&q, &dq, Order::Dynamics, &mut self.terms);
                let m = &self.terms.mass;
                let mdd = DMatrix::from_fn(nd, nd, |r, c| m[(self.dynamic[r], self.dynamic[c])]);
                let lu = mdd.lu();
                let mut rhs = DVector::from_fn(nd, |r, _| x[nd + r]);
                for (r, &i) in self.dynamic.iter().enumerate() {
                    for &j in &self.kinematic {
                        rhs[r] -= m[(i, j)] * dq[j];
                    }
                }
                let v = lu.solve(&rhs).ok_or_else(|| SimError::InvalidInput(
                    "the mass matrix of the dynamic variables is singular: no velocity matches the momentum".into(),
                ))?;
                for (r, &i) in self.dynamic.iter().enumerate() {
                    dq[i] = v[r];
                }
                if derivatives {
                    // M_dd dq̇_d = dp_d − (∂²L/∂q̇_d∂q) dq − M_dk dq̇_k, at the true q̇.
                    self.sys
                        .lagrangian(&q, &dq, Order::Dynamics, &mut self.terms);
                    let m = &self.terms.mass;
                    let mut rhs = DMatrix::zeros(nd, nx);
                    for (r, &i) in self.dynamic.iter().enumerate() {
                        rhs[(r, nd + r)] = 1.0;
                        for c in 0..nx {
                            let mut s = 0.0;
                            for j in 0..n {
                                s += self.terms.d2l_ddq_dq[(i, j)] * out.q_x[(j, c)];
                            }
                            for &j in &self.kinematic {
                                s += m[(i, j)] * out.dq_x[(j, c)];
                            }
                            rhs[(r, c)] -= s;
                        }
                    }
                    let sol = lu.solve(&rhs).expect("factored above");
                    for (r, &i) in self.dynamic.iter().enumerate() {
                        for c in 0..nx {
                            out.dq_x[(i, c)] = sol[(r, c)];
                        }
                    }
                }
            }
        }
        out.q.as_mut_slice().copy_from_slice(q.as_slice());
        out.dq.as_mut_slice().copy_from_slice(dq.as_slice());
        if gravity {
            let zero = self.sys.zero_vector();
            let order = if derivatives {
                Order::Full
            } else {
                Order::First
            };
            self.sys.lagrangian(&q, &zero, order, &mut self.terms);
            out.gravity_x.fill(0.0);
            for (c, control) in self.controls.iter().enumerate() {
                out.gravity[c] = 0.0;
                if let Control::Input(kin) = *control {
                    let i = self.sys.input_variable(kin);
                    out.gravity[c] = -self.terms.dl_dq[i];
                    if derivatives {
                        for col in 0..nx {
                            let mut s = 0.0;
                            for j in 0..n {
                                s -= self.terms.d2l_dq_dq[(i, j)] * out.q_x[(j, col)];
                            }
                            out.gravity_x[(c, col)] = s;
                        }
                    }
                }
            }
        }
        if !(out
            .dq
            .iter()
            .chain(out.gravity.iter())
            .all(|v| v.is_finite()))
        {
            return Err(SimError::InvalidInput(format!(
                "the velocity or gravity compensation at knot {k} is not finite"
            )));
        }
        Ok(())
    }

    /// Sets up step `k` from `x` with controls `u`: `q1`, `p1` (VI) or `q̇1` (RK4), the
    /// model's inputs, and the controlled kinematic variables' `(i, k₁, k₂)`.
    fn begin(&mut self, k: usize, x: &[f64], u: &[f64], controlled: &mut Vec<(usize, f64, f64)>) {
        let nd = self.dynamic.len();
        let mut q1 = std::mem::replace(&mut self.q1, self.sys.zero_vector());
        let mut p1 = std::mem::replace(&mut self.p1, self.sys.zero_vector());
        self.place(k, x, &mut q1, Some(&mut p1));
        for (r, &i) in self.dynamic.iter().enumerate() {
            p1[i] = x[nd + r];
        }
        if self.is_vi() {
            for &i in &self.kinematic {
                p1[i] = 0.0;
            }
        }
        self.q1 = q1;
        self.p1 = p1;
        self.inputs.iter_mut().for_each(|v| *v = 0.0);
        controlled.clear();
        for (c, control) in self.controls.iter().enumerate() {
            match *control {
                Control::Input(kin) => self.inputs[kin] = u[c],
                Control::Kinematic(i) => controlled.push((i, x[self.memory[c]], u[c])),
            }
        }
    }

    /// `x₂ = f_k(x₁, u)`; with `jacobians`, also `A = ∂x₂/∂x₁`, `B = ∂x₂/∂u`.
    pub fn step(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        x2: &mut [f64],
        jacobians: Option<(&mut DMatrix<f64>, &mut DMatrix<f64>)>,
    ) -> Result<(), SimError> {
        let nd = self.dynamic.len();
        let n = self.sys.dof();
        let t = self.t0 + k as f64 * self.dt;
        let mut controlled = Vec::with_capacity(self.controls.len());
        self.begin(k, x, u, &mut controlled);
        let mut force = NoForce;
        let mut motion = Decided {
            model: &mut self.motion,
            controlled: &controlled,
            t1: t,
            dt: self.dt,
        };
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, self.dt);
        cx.u = &self.inputs;
        cx.at(k, t);
        let (mut a, mut b) = match jacobians {
            Some((a, b)) => {
                a.fill(0.0);
                b.fill(0.0);
                (Some(a), Some(b))
            }
            None => (None, None),
        };
        match &mut self.method {
            Method::Vi(vi) => {
                self.q2.copy_from(&self.q1);
                self.p2.copy_from(&self.p1);
                vi.last_velocity.fill(0.0);
                vi.step(&mut cx, &mut self.q2, &mut self.p2, &mut self.next)?;
                for (r, &i) in self.dynamic.iter().enumerate() {
                    x2[r] = self.q2[i];
                    x2[nd + r] = self.p2[i];
                }
                if let (Some(a), Some(b)) = (a.as_mut(), b.as_mut()) {
                    vi.derivatives_into(&mut cx, &self.q1, &self.p1, &self.q2, &mut self.first)?;
                    let d = &self.first;
                    for r in 0..nd {
                        for (c, &j) in self.dynamic.iter().enumerate() {
                            a[(r, c)] = d.q2_dq1[(r, j)];
                            a[(nd + r, c)] = d.p2_dq1[(r, j)];
                            a[(r, nd + c)] = d.q2_dp1[(r, c)];
                            a[(nd + r, nd + c)] = d.p2_dp1[(r, c)];
                        }
                        for (c, control) in self.controls.iter().enumerate() {
                            match *control {
                                Control::Input(kin) => {
                                    b[(r, c)] = d.q2_du1[(r, kin)];
                                    b[(nd + r, c)] = d.p2_du1[(r, kin)];
                                }
                                Control::Kinematic(i) => {
                                    let col = self.kinematic.iter().position(|&j| j == i).unwrap();
                                    b[(r, c)] = d.q2_dk2[(r, col)];
                                    b[(nd + r, c)] = d.p2_dk2[(r, col)];
                                    a[(r, self.memory[c])] = d.q2_dq1[(r, i)];
                                    a[(nd + r, self.memory[c])] = d.p2_dq1[(r, i)];
                                }
                            }
                        }
                    }
                }
            }
            Method::Rk4(rk4) => {
                if let (Some(a), Some(b)) = (a.as_mut(), b.as_mut()) {
                    let (q1, v1) = (self.q1.clone(), self.p1.clone());
                    let d = explicit_step_derivatives(&mut cx, &q1, &v1, &RK4)?;
                    x2[..2 * nd].copy_from_slice(d.x2.as_slice());
                    a.view_mut((0, 0), (2 * nd, 2 * nd)).copy_from(&d.x2_dx1);
                    for (c, control) in self.controls.iter().enumerate() {
                        if let Control::Input(kin) = *control {
                            b.view_mut((0, c), (2 * nd, 1))
                                .copy_from(&d.x2_du1.column(kin));
                        }
                    }
                } else {
                    self.q2.copy_from(&self.q1);
                    self.p2.copy_from(&self.p1);
                    rk4.step(&mut cx, &mut self.q2, &mut self.p2)?;
                    for (r, &i) in self.dynamic.iter().enumerate() {
                        x2[r] = self.q2[i];
                        x2[nd + r] = self.p2[i];
                    }
                }
            }
        }
        // The memory: inputs remember their value, kinematic controls value and velocity.
        for (c, control) in self.controls.iter().enumerate() {
            let at = self.memory[c];
            x2[at] = u[c];
            if let Some(b) = b.as_mut() {
                b[(at, c)] = 1.0;
            }
            if let Control::Kinematic(_) = control {
                x2[at + 1] = (u[c] - x[at]) / self.dt;
                if let (Some(a), Some(b)) = (a.as_mut(), b.as_mut()) {
                    b[(at + 1, c)] = 1.0 / self.dt;
                    a[(at + 1, at)] = -1.0 / self.dt;
                }
            }
        }
        let _ = n;
        if x2.iter().any(|v| !v.is_finite()) {
            return Err(SimError::InvalidInput(format!(
                "the state after step {k} is not finite"
            )));
        }
        Ok(())
    }

    /// The step's second derivatives from knot `k` with `(x, u)` contracted with `v` on
    /// `x₂` (DDP's `V_x'·f_xx` terms) into `hxx` (states²), `huu` (controls²) and `hux`
    /// (controls × states). The VI only (the memory is linear, so only `(q₂, p₂)` count).
    #[allow(clippy::too_many_arguments)]
    pub fn contracted(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        v: &[f64],
        hxx: &mut DMatrix<f64>,
        huu: &mut DMatrix<f64>,
        hux: &mut DMatrix<f64>,
    ) -> Result<(), SimError> {
        let mut x2 = vec![0.0; self.states()];
        self.step(k, x, u, &mut x2, None)?;
        let nd = self.dynamic.len();
        let n = self.sys.dof();
        let ni = self.sys.input_count();
        for r in 0..nd {
            self.covector.q2[r] = v[r];
            self.covector.p2[r] = v[nd + r];
        }
        let t = self.t0 + k as f64 * self.dt;
        let mut controlled = Vec::with_capacity(self.controls.len());
        self.begin(k, x, u, &mut controlled);
        let Method::Vi(vi) = &mut self.method else {
            return Err(SimError::InvalidInput(
                "DDP needs the VI's second derivatives: use iLQR with RK4".into(),
            ));
        };
        let mut force = NoForce;
        let mut motion = Decided {
            model: &mut self.motion,
            controlled: &controlled,
            t1: t,
            dt: self.dt,
        };
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, self.dt);
        cx.u = &self.inputs;
        cx.at(k, t);
        vi.contracted_second_derivatives(
            &mut cx,
            &self.q1,
            &self.p1,
            &self.q2,
            &self.covector,
            &mut self.hessian,
        )?;
        // The step's columns: (q₁ all n, p₁ n_d, u₁ every input, k₂ every kinematic).
        let nx = self.states();
        let state = |c: usize| -> Option<usize> {
            if c < nd {
                return Some(self.dynamic[c]);
            }
            if c < 2 * nd {
                return Some(n + c - nd);
            }
            self.controls
                .iter()
                .enumerate()
                .find_map(|(j, control)| match *control {
                    Control::Kinematic(i) if self.memory[j] == c => Some(i),
                    _ => None,
                })
        };
        let control = |c: usize| -> usize {
            match self.controls[c] {
                Control::Input(kin) => n + nd + kin,
                Control::Kinematic(i) => {
                    n + nd + ni + self.kinematic.iter().position(|&j| j == i).unwrap()
                }
            }
        };
        let nu = u.len();
        hxx.fill(0.0);
        hux.fill(0.0);
        for r in 0..nx {
            let Some(sr) = state(r) else { continue };
            for c in 0..nx {
                if let Some(sc) = state(c) {
                    hxx[(r, c)] = self.hessian[(sr, sc)];
                }
            }
        }
        for a in 0..nu {
            for b in 0..nu {
                huu[(a, b)] = self.hessian[(control(a), control(b))];
            }
            for c in 0..nx {
                if let Some(sc) = state(c) {
                    hux[(a, c)] = self.hessian[(control(a), sc)];
                }
            }
        }
        Ok(())
    }
}
