//! A system discretised in time as a control system `x_{k+1} = f_k(x_k, u_k)`, by the
//! midpoint VI (default) or RK4 (docs/derivations.md §10).
//!
//! The state is `x = (q_d, v_d, m)`: the dynamic variables' configuration, their momentum
//! `p_d` (VI) or velocity `q̇_d` (RK4), and a memory `m` of the controls — for each input
//! its previous value (what a `control_rate` term differences against; left out with
//! [`DiscreteSystem::with_input_memory`] when no cost reads it), for each kinematic control
//! its value and velocity `(ρ_k − ρ_{k−1})/Δt` at the knot (trep's `(q_k, v_k)`).
//! The controls `u_k` are the chosen inputs, held over step k, and the chosen kinematic
//! variables' values at knot `k + 1` (trep's ρ), linear in time over the step; every other
//! input is zero and every other kinematic variable follows its prescription.

use nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};

use crate::knot::{Knot, Needs};
use tree_model::Control;
use tree_runtime::dynamics::{ModelMotions, NoForce, Prescription};
use tree_runtime::integrate::{
    MidpointVi, Rk4, StepCovector, StepDerivatives, StepInput, StepOutput, ViSettings,
};
use tree_runtime::linalg::{lu_factor_packed, lu_solve_packed, lu_solve_packed_rows};
use tree_runtime::linearize::{
    explicit_step_derivatives_into, ExplicitStepDerivatives, ExplicitStepWorkspace, RK4,
};
use tree_runtime::SimError;
use tree_runtime::StepContext;
use tree_runtime::{ConstraintTerms, Order, System, Terms, Vector};

/// A unilateral row within this gap (m or rad) of closing touches, for
/// [`DiscreteSystem::holding_inputs`].
const TOUCH: f64 = 1e-3;

/// The weight ε of the contact forces against the inputs in
/// [`DiscreteSystem::holding_inputs`]: small, so the contacts carry what they can.
const FORCE_WEIGHT: f64 = 1e-3;

/// The discretisation.
enum Stepper<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    Vi(Box<MidpointVi<N>>),
    Rk4(Box<ExplicitStep<N>>),
}

/// RK4's stepper, and the buffers of its step derivatives.
struct ExplicitStep<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    rk4: Rk4<N>,
    workspace: ExplicitStepWorkspace<N>,
    derivatives: ExplicitStepDerivatives,
}

/// One input coordinate of the VI step (§9's `x = (q₁, p₁, u₁, k₂)`): which block and which
/// column of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StepColumn {
    /// Variable j of `q₁`.
    Q1(usize),
    /// Dynamic variable r of `p₁`.
    P1(usize),
    /// Input k.
    U1(usize),
    /// Kinematic variable at position r of `k₂`.
    K2(usize),
}

impl StepColumn {
    /// Its block and column in [`StepDerivatives`].
    fn block(self) -> (StepInput, usize) {
        match self {
            StepColumn::Q1(j) => (StepInput::Q1, j),
            StepColumn::P1(r) => (StepInput::P1, r),
            StepColumn::U1(k) => (StepInput::U1, k),
            StepColumn::K2(r) => (StepInput::K2, r),
        }
    }

    /// Its index in the contracted Hessian over `(q₁ n, p₁ n_d, u₁ inputs, k₂)`.
    fn index(self, n: usize, nd: usize, inputs: usize) -> usize {
        match self {
            StepColumn::Q1(j) => j,
            StepColumn::P1(r) => n + r,
            StepColumn::U1(k) => n + nd + k,
            StepColumn::K2(r) => n + nd + inputs + r,
        }
    }
}

/// Where everything sits: the dynamic and kinematic variables, the controls, each control's
/// memory in `x`, and which step input each entry of `x` and `u` is (for reading `A`, `B`
/// and DDP's Hessian off the step's derivatives).
struct Layout {
    controls: Vec<Control>,
    dynamic: Vec<usize>,
    kinematic: Vec<usize>,
    /// Per control, its memory's first slot in `x` (None: an input not remembered).
    memory: Vec<Option<usize>>,
    /// Whether inputs are remembered.
    input_memory: bool,
    /// The state's size.
    states: usize,
    /// Per entry of `x`, the step input it is (None: a velocity or input memory, which the
    /// step does not read).
    x_column: Vec<Option<StepColumn>>,
    /// Per control, the step input it is.
    u_column: Vec<StepColumn>,
}

impl Layout {
    fn new(
        dynamic: Vec<usize>,
        kinematic: Vec<usize>,
        controls: Vec<Control>,
        input_memory: bool,
    ) -> Self {
        let nd = dynamic.len();
        let mut x_column: Vec<Option<StepColumn>> = dynamic
            .iter()
            .map(|&i| Some(StepColumn::Q1(i)))
            .chain((0..nd).map(|r| Some(StepColumn::P1(r))))
            .collect();
        let (mut memory, mut u_column) = (Vec::new(), Vec::new());
        for c in &controls {
            match *c {
                Control::Input(k) => {
                    memory.push(input_memory.then_some(x_column.len()));
                    if input_memory {
                        x_column.push(None);
                    }
                    u_column.push(StepColumn::U1(k));
                }
                Control::Kinematic(i) => {
                    memory.push(Some(x_column.len()));
                    x_column.extend([Some(StepColumn::Q1(i)), None]);
                    let at = kinematic
                        .iter()
                        .position(|&j| j == i)
                        .expect("checked kinematic");
                    u_column.push(StepColumn::K2(at));
                }
            }
        }
        Layout {
            input_memory,
            states: x_column.len(),
            controls,
            dynamic,
            kinematic,
            memory,
            x_column,
            u_column,
        }
    }

    /// The configuration at time `t` of state `x` (controlled kinematic variables from the
    /// memory, the others on their prescription) into `q`, and the kinematic velocities into
    /// `dq` (its dynamic entries untouched).
    fn place<N: nalgebra::Dim>(
        &self,
        motion: &mut ModelMotions,
        t: f64,
        x: &[f64],
        q: &mut Vector<N>,
        dq: &mut Vector<N>,
    ) where
        DefaultAllocator: Allocator<N>,
    {
        for (r, &i) in self.dynamic.iter().enumerate() {
            q[i] = x[r];
        }
        for &i in &self.kinematic {
            [q[i], dq[i], _] = motion.kinematic(i, t);
        }
        for (c, control) in self.controls.iter().enumerate() {
            if let (Control::Kinematic(i), Some(at)) = (*control, self.memory[c]) {
                (q[i], dq[i]) = (x[at], x[at + 1]);
            }
        }
    }
}

/// A step's buffers: its start and end, the derivatives and the contraction.
struct Buffers<N: nalgebra::Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, N>,
{
    q1: Vector<N>,
    p1: Vector<N>,
    q2: Vector<N>,
    p2: Vector<N>,
    next: Vector<N>,
    /// `(variable, value at t₁, value at t₁ + Δt)` of each kinematic control.
    controlled: Vec<(usize, f64, f64)>,
    /// The model's inputs over the step (the controlled ones from `u`, the rest zero).
    inputs: Vec<f64>,
    first: StepDerivatives,
    hessian: DMatrix<f64>,
    covector: StepCovector,
    terms: Terms<N>,
    /// A knot's velocity from its momentum: `M_dd`'s LU factor (column-major), its pivots,
    /// the right-hand sides (row-major `n_d × states`: the velocity's, then its derivative's).
    mdd: Vec<f64>,
    pivots: Vec<usize>,
    velocity_rhs: Vec<f64>,
}

/// The system as `x_{k+1} = f_k(x_k, u_k)`. On the VI, steps, their Jacobians and second
/// derivatives and knots (velocity from the momentum included) allocate nothing after the
/// first (tests/allocation.rs); RK4's step derivatives still allocate temporaries.
pub struct DiscreteSystem<S: System>
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    /// The system.
    pub sys: S,
    method: Stepper<S::N>,
    motion: ModelMotions,
    /// The step length.
    pub dt: f64,
    /// The time of knot 0.
    pub t0: f64,
    layout: Layout,
    buf: Buffers<S::N>,
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
    pub fn new(sys: S, settings: ViSettings, dt: f64, t0: f64) -> Result<Self, SimError> {
        let controls = (0..sys.input_count()).map(Control::Input).collect();
        Self::vi(sys, settings, dt, t0, controls)
    }

    /// The VI with the given controls (inputs and kinematic variables). Its steps are never
    /// subdivided (a subdivided step's derivatives would not be those of one step): a step
    /// Newton cannot take fails, and the optimiser's line search backs off.
    pub fn vi(
        sys: S,
        settings: ViSettings,
        dt: f64,
        t0: f64,
        controls: Vec<Control>,
    ) -> Result<Self, SimError> {
        let settings = ViSettings {
            max_subdivisions: 0,
            ..settings
        };
        let vi = MidpointVi::new(&sys, settings);
        Self::build(sys, Stepper::Vi(Box::new(vi)), dt, t0, controls)
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
        let rk4 = Box::new(ExplicitStep {
            rk4: Rk4::new(&sys),
            workspace: ExplicitStepWorkspace::new(&sys),
            derivatives: ExplicitStepDerivatives::empty(),
        });
        Self::build(sys, Stepper::Rk4(rk4), dt, t0, controls)
    }

    fn build(
        sys: S,
        method: Stepper<S::N>,
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
        let z = sys.zero_vector();
        let buf = Buffers {
            q1: z.clone(),
            p1: z.clone(),
            q2: z.clone(),
            p2: z.clone(),
            next: z,
            controlled: Vec::with_capacity(controls.len()),
            inputs: vec![0.0; sys.input_count()],
            first: StepDerivatives::empty(),
            hessian: DMatrix::zeros(0, 0),
            covector: StepCovector {
                q2: DVector::zeros(nd),
                p2: DVector::zeros(nd),
                lambda: DVector::zeros(sys.constraint_count()),
            },
            terms: Terms::zeros(sys.dim()),
            mdd: vec![0.0; nd * nd],
            pivots: vec![0; nd],
            velocity_rhs: Vec::new(),
        };
        Ok(DiscreteSystem {
            motion: ModelMotions::of(&sys),
            layout: Layout::new(dynamic, kinematic, controls, true),
            buf,
            method,
            dt,
            t0,
            sys,
        })
    }

    /// Whether the state remembers each input's previous value (as built: yes).
    pub(crate) fn has_input_memory(&self) -> bool {
        self.layout.input_memory
    }

    /// With `keep = false`, the state leaves out the inputs' memory: `x` is `2 n_d` plus the
    /// kinematic controls' value and velocity, and [`Knot::previous`] is 0 on inputs. For
    /// costs that do not difference inputs against their previous values (no `control_rate`
    /// on an input), a smaller state makes every backward-pass product cheaper.
    pub fn with_input_memory(mut self, keep: bool) -> Self {
        let l = &self.layout;
        let (dynamic, kinematic) = (l.dynamic.clone(), l.kinematic.clone());
        self.layout = Layout::new(dynamic, kinematic, l.controls.clone(), keep);
        self
    }

    /// The state's size: `2 n_d` plus the controls' memory.
    pub fn states(&self) -> usize {
        self.layout.states
    }

    /// The number of controls.
    pub fn controls(&self) -> usize {
        self.layout.controls.len()
    }

    /// Whether this is the VI (otherwise RK4).
    pub(crate) fn is_vi(&self) -> bool {
        matches!(self.method, Stepper::Vi(_))
    }

    /// The constraint multipliers of the last step (VI: `λ` of the step; RK4: none).
    pub fn multipliers(&self) -> &[f64] {
        match &self.method {
            Stepper::Vi(vi) => vi.lambda.as_slice(),
            Stepper::Rk4(_) => &[],
        }
    }

    /// The state of `(q, q̇)` at knot 0, the controls' memory from `previous` (their values
    /// "before" the start: the initial guess of inputs; kinematic controls take their value
    /// and velocity from `q`, `q̇`).
    pub fn state_of(
        &mut self,
        q: &Vector<S::N>,
        dq: &Vector<S::N>,
        previous: &[f64],
    ) -> DVector<f64> {
        let l = &self.layout;
        let nd = l.dynamic.len();
        let mut x = DVector::zeros(l.states);
        let v = match &mut self.method {
            Stepper::Vi(vi) => vi.initial_momentum(&mut self.sys, q, dq),
            Stepper::Rk4(_) => dq.clone(),
        };
        for (r, &i) in l.dynamic.iter().enumerate() {
            x[r] = q[i];
            x[nd + r] = v[i];
        }
        for (c, control) in l.controls.iter().enumerate() {
            let Some(at) = l.memory[c] else { continue };
            match *control {
                Control::Input(_) => x[at] = previous.get(c).copied().unwrap_or(0.0),
                Control::Kinematic(i) => (x[at], x[at + 1]) = (q[i], dq[i]),
            }
        }
        x
    }

    /// `G = −∂L/∂q` at `(q, q̇ = 0)`: the generalized force that holds `q` at rest.
    fn generalized_gravity(&mut self, q: &Vector<S::N>) -> DVector<f64> {
        let zero = self.sys.zero_vector();
        let terms = &mut self.buf.terms;
        self.sys.lagrangian(q, &zero, Order::First, terms);
        DVector::from_fn(q.len(), |i, _| -terms.dl_dq[i])
    }

    /// A generalized force's entries on each control's input variable (zero for kinematic
    /// controls).
    fn per_input(&self, g: &DVector<f64>) -> DVector<f64> {
        DVector::from_fn(self.layout.controls.len(), |c, _| {
            match self.layout.controls[c] {
                Control::Input(k) => g[self.sys.input_variable(k)],
                Control::Kinematic(_) => 0.0,
            }
        })
    }

    /// The unilateral rows that touch at `q` (gap within [`TOUCH`]; a frictional contact's
    /// tangent rows with its gap row), and every row's terms there.
    pub(crate) fn touching(&mut self, q: &Vector<S::N>) -> (Vec<usize>, ConstraintTerms) {
        let gaps = self.sys.unilateral();
        let rows: usize = gaps.iter().map(|g| g.rows()).sum();
        let mut terms = ConstraintTerms::zeros(rows, q.len());
        self.sys.gaps(q, None, &mut terms);
        let (mut touching, mut row) = (Vec::new(), 0);
        for g in &gaps {
            if terms.h[row] <= TOUCH {
                touching.extend(row..row + g.rows());
            }
            row += g.rows();
        }
        (touching, terms)
    }

    /// The inputs that hold `q` at rest where the model touches something: the generalized
    /// force `G = −∂L/∂q` at `q̇ = 0` balanced by the inputs `B u` and by the forces `Aᵀf` of
    /// the unilateral rows that touch at `q` (gap within [`TOUCH`]; a frictional contact's
    /// tangent rows with it) — `B u + Aᵀ f = G` with the least inputs, then the least forces
    /// (`min ‖u‖² + ε²‖f‖²`, ε = [`FORCE_WEIGHT`]); the equilibrium in least squares where
    /// none holds exactly. A legged robot crouched on the ground is held by its feet as well
    /// as its motors, where the plain gravity compensation (`G` on each input's own row)
    /// holds its legs up as if they hung. Without touching rows, that compensation. The
    /// friction cones are not imposed.
    pub(crate) fn holding_inputs(&mut self, q: &Vector<S::N>) -> DVector<f64> {
        let (touching, terms) = self.touching(q);
        let g = self.generalized_gravity(q);
        let hold = self.per_input(&g);
        if touching.is_empty() {
            return hold;
        }
        let (n, nu) = (q.len(), self.layout.controls.len());
        let mut c = DMatrix::zeros(n, nu + touching.len());
        for (k, control) in self.layout.controls.iter().enumerate() {
            if let Control::Input(input) = *control {
                c[(self.sys.input_variable(input), k)] = 1.0;
            }
        }
        for (j, &r) in touching.iter().enumerate() {
            for i in 0..n {
                c[(i, nu + j)] = terms.dh[(r, i)] / FORCE_WEIGHT;
            }
        }
        match c.svd(true, true).solve(&g, 1e-12) {
            Ok(x) => DVector::from_fn(nu, |k, _| x[k]),
            Err(_) => hold,
        }
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
        self.place_knot(k, x, out, derivatives);
        let nd = self.layout.dynamic.len();
        match self.method {
            Stepper::Rk4(_) => {
                let dq = &mut self.buf.p1;
                for (r, &i) in self.layout.dynamic.iter().enumerate() {
                    dq[i] = x[nd + r];
                    if derivatives {
                        out.dq_x[(i, nd + r)] = 1.0;
                    }
                }
            }
            Stepper::Vi(_) if !needs.velocity => {}
            Stepper::Vi(_) => self.velocity_from_momentum(k, x, out, derivatives)?,
        }
        out.q.as_mut_slice().copy_from_slice(self.buf.q1.as_slice());
        out.dq
            .as_mut_slice()
            .copy_from_slice(self.buf.p1.as_slice());
        if needs.gravity {
            self.knot_gravity(out, derivatives);
        }
        if let Some(bad) = out
            .dq
            .iter()
            .chain(out.gravity.iter())
            .find(|v| !v.is_finite())
        {
            return Err(SimError::InvalidInput(format!(
                "the velocity or gravity compensation at knot {k} is not finite ({bad})"
            )));
        }
        Ok(())
    }

    /// Knot `k`'s buffers sized, `x` and the controls' previous values copied, `q` and the
    /// kinematic `q̇` placed in the step buffers (the dynamic `q̇` zero until known), and (with
    /// `derivatives`) the columns of `∂q/∂x`, `∂q̇_k/∂x` that select one entry each.
    fn place_knot(&mut self, k: usize, x: &[f64], out: &mut Knot, derivatives: bool) {
        let l = &self.layout;
        let (n, nx, nu) = (self.sys.dof(), l.states, l.controls.len());
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
                previous_at: l.memory.clone(),
            };
        }
        out.x.as_mut_slice().copy_from_slice(x);
        let (q, dq) = (&mut self.buf.q1, &mut self.buf.p1);
        dq.as_mut_slice().fill(0.0);
        l.place(&mut self.motion, self.t0 + k as f64 * self.dt, x, q, dq);
        for c in 0..nu {
            out.previous[c] = l.memory[c].map_or(0.0, |at| x[at]);
        }
        if derivatives {
            out.q_x.as_mut_slice().fill(0.0);
            out.dq_x.as_mut_slice().fill(0.0);
            for (c, column) in l.x_column.iter().enumerate() {
                if let Some(StepColumn::Q1(i)) = *column {
                    out.q_x[(i, c)] = 1.0;
                    if l.kinematic.contains(&i) {
                        out.dq_x[(i, c + 1)] = 1.0;
                    }
                }
            }
        }
    }

    /// The VI's dynamic velocities from the state's momenta into the step buffer, and (with
    /// `derivatives`) their Jacobian `∂q̇_d/∂x` into `out`.
    fn velocity_from_momentum(
        &mut self,
        k: usize,
        x: &[f64],
        out: &mut Knot,
        derivatives: bool,
    ) -> Result<(), SimError> {
        let l = &self.layout;
        let (nx, nd) = (l.states, l.dynamic.len());
        let (q, dq) = (&mut self.buf.q1, &mut self.buf.p1);
        let (terms, mdd, pivots, rhs) = (
            &mut self.buf.terms,
            &mut self.buf.mdd,
            &mut self.buf.pivots,
            &mut self.buf.velocity_rhs,
        );
        // q̇_d = M_dd⁻¹ (p_d − M_dk q̇_k): L is quadratic in q̇, so p = M q̇ (M does
        // not depend on q̇, so q̇_d = 0 here is as good as any).
        self.sys.mass_matrix(q, terms);
        let m = &terms.mass;
        for (c, &j) in l.dynamic.iter().enumerate() {
            for (r, &i) in l.dynamic.iter().enumerate() {
                mdd[c * nd + r] = m[(i, j)];
            }
        }
        let singular = || {
            SimError::InvalidInput(format!(
                "at knot {k} the mass matrix of the dynamic variables is singular: no velocity matches the momentum"
            ))
        };
        lu_factor_packed(mdd, nd, pivots).map_err(|_| singular())?;
        rhs.resize(nd * nx, 0.0);
        for (r, &i) in l.dynamic.iter().enumerate() {
            rhs[r] = x[nd + r];
            for &j in &l.kinematic {
                rhs[r] -= m[(i, j)] * dq[j];
            }
        }
        lu_solve_packed(mdd, nd, pivots, &mut rhs[..nd]);
        for (r, &i) in l.dynamic.iter().enumerate() {
            dq[i] = rhs[r];
        }
        if dq.iter().any(|v| !v.is_finite()) {
            return Err(singular());
        }
        if derivatives {
            // M_dd dq̇_d = dp_d − (∂²L/∂q̇_d∂q) dq − M_dk dq̇_k, at the true q̇; dq/dx
            // and dq̇_k/dx select one column each (set above), so the products are
            // lookups.
            self.sys.lagrangian(q, dq, Order::Dynamics, terms);
            let m = &terms.mass;
            let rhs = &mut rhs[..nd * nx];
            rhs.fill(0.0);
            for r in 0..nd {
                rhs[r * nx + nd + r] = 1.0;
            }
            for (c, column) in l.x_column.iter().enumerate() {
                let Some(StepColumn::Q1(j)) = *column else {
                    continue;
                };
                let kinematic = l.kinematic.contains(&j);
                for (r, &i) in l.dynamic.iter().enumerate() {
                    rhs[r * nx + c] -= terms.d2l_ddq_dq[(i, j)];
                    if kinematic {
                        rhs[r * nx + c + 1] -= m[(i, j)];
                    }
                }
            }
            lu_solve_packed_rows(mdd, nd, pivots, rhs, nx);
            for (r, &i) in l.dynamic.iter().enumerate() {
                for c in 0..nx {
                    out.dq_x[(i, c)] = rhs[r * nx + c];
                }
            }
        }
        Ok(())
    }

    /// The gravity compensation of each input control, `g = −∂L/∂q` at `q̇ = 0` on its
    /// variable, and (with `derivatives`) its Jacobian by the state.
    fn knot_gravity(&mut self, out: &mut Knot, derivatives: bool) {
        let l = &self.layout;
        let (q, dq, terms) = (&mut self.buf.q1, &mut self.buf.p1, &mut self.buf.terms);
        dq.as_mut_slice().fill(0.0);
        let order = if derivatives {
            Order::Full
        } else {
            Order::First
        };
        self.sys.lagrangian(q, dq, order, terms);
        out.gravity_x.as_mut_slice().fill(0.0);
        for (c, control) in l.controls.iter().enumerate() {
            out.gravity[c] = 0.0;
            if let Control::Input(kin) = *control {
                let i = self.sys.input_variable(kin);
                out.gravity[c] = -terms.dl_dq[i];
                if derivatives {
                    // dq/dx selects one column per variable.
                    for (col, column) in l.x_column.iter().enumerate() {
                        if let Some(StepColumn::Q1(j)) = *column {
                            out.gravity_x[(c, col)] = -terms.d2l_dq_dq[(i, j)];
                        }
                    }
                }
            }
        }
    }

    /// Sets up step `k` from `x` with controls `u` (`q₁`, `p₁` (VI) or `q̇₁` (RK4), the
    /// model's inputs, the kinematic controls' `(i, k₁, k₂)`), then runs `f` with the step's
    /// context, its method and buffers.
    fn with_step<R>(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        f: impl FnOnce(
            &mut Stepper<S::N>,
            &mut StepContext<S, NoForce, Decided>,
            &Layout,
            &mut Buffers<S::N>,
        ) -> R,
    ) -> R {
        let (l, b) = (&self.layout, &mut self.buf);
        let nd = l.dynamic.len();
        let t = self.t0 + k as f64 * self.dt;
        b.p1.as_mut_slice().fill(0.0);
        l.place(&mut self.motion, t, x, &mut b.q1, &mut b.p1);
        for (r, &i) in l.dynamic.iter().enumerate() {
            b.p1[i] = x[nd + r];
        }
        if matches!(self.method, Stepper::Vi(_)) {
            // The VI's p₁ has dynamic entries only.
            for &i in &l.kinematic {
                b.p1[i] = 0.0;
            }
        }
        b.inputs.as_mut_slice().fill(0.0);
        b.controlled.clear();
        for (c, control) in l.controls.iter().enumerate() {
            match *control {
                Control::Input(kin) => b.inputs[kin] = u[c],
                Control::Kinematic(i) => {
                    let at = l.memory[c].expect("kinematic controls are remembered");
                    b.controlled.push((i, x[at], u[c]))
                }
            }
        }
        let controlled = std::mem::take(&mut b.controlled);
        let inputs = std::mem::take(&mut b.inputs);
        let mut force = NoForce;
        let mut motion = Decided {
            model: &mut self.motion,
            controlled: &controlled,
            t1: t,
            dt: self.dt,
        };
        let mut cx = StepContext::new(&mut self.sys, &mut force, &mut motion, self.dt);
        cx.u = &inputs;
        cx.at(k, t);
        let out = f(&mut self.method, &mut cx, l, b);
        b.controlled = controlled;
        b.inputs = inputs;
        out
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
        let dt = self.dt;
        let mut jacobians = jacobians;
        if let Some((a, b)) = jacobians.as_mut() {
            a.as_mut_slice().fill(0.0);
            b.as_mut_slice().fill(0.0);
        }
        self.with_step(k, x, u, |method, cx, l, b| {
            let nd = l.dynamic.len();
            match method {
                Stepper::Vi(vi) => {
                    b.q2.copy_from(&b.q1);
                    b.p2.copy_from(&b.p1);
                    vi.predict_from_rest();
                    vi.settings.derivatives = jacobians.is_some();
                    vi.step(cx, &mut b.q2, &mut b.p2, &mut b.next)?;
                    for (r, &i) in l.dynamic.iter().enumerate() {
                        x2[r] = b.q2[i];
                        x2[nd + r] = b.p2[i];
                    }
                    if let Some((a, bm)) = jacobians.as_mut() {
                        vi.derivatives_into(cx, &b.q1, &b.p1, &b.q2, &mut b.first)?;
                        read_jacobians(l, &b.first, a, bm);
                    }
                }
                Stepper::Rk4(explicit) => {
                    if let Some((a, bm)) = jacobians.as_mut() {
                        let (ws, d) = (&mut explicit.workspace, &mut explicit.derivatives);
                        explicit_step_derivatives_into(cx, &b.q1, &b.p1, &RK4, ws, d)?;
                        x2[..2 * nd].copy_from_slice(d.x2.as_slice());
                        a.view_mut((0, 0), (2 * nd, 2 * nd)).copy_from(&d.x2_dx1);
                        for (c, &col) in l.u_column.iter().enumerate() {
                            if let StepColumn::U1(kin) = col {
                                bm.view_mut((0, c), (2 * nd, 1))
                                    .copy_from(&d.x2_du1.column(kin));
                            }
                        }
                    } else {
                        b.q2.copy_from(&b.q1);
                        b.p2.copy_from(&b.p1);
                        explicit.rk4.step(cx, &mut b.q2, &mut b.p2)?;
                        for (r, &i) in l.dynamic.iter().enumerate() {
                            x2[r] = b.q2[i];
                            x2[nd + r] = b.p2[i];
                        }
                    }
                }
            }
            // The memory: inputs remember their value, kinematic controls value and velocity.
            for (c, control) in l.controls.iter().enumerate() {
                let Some(at) = l.memory[c] else { continue };
                x2[at] = u[c];
                if let Control::Kinematic(_) = control {
                    x2[at + 1] = (u[c] - x[at]) / dt;
                }
            }
            if let Some((a, bm)) = jacobians.as_mut() {
                memory_jacobians(l, dt, a, bm);
            }
            match x2.iter().find(|v| !v.is_finite()) {
                Some(v) => Err(SimError::InvalidInput(format!(
                    "the state after step {k} is not finite ({v})"
                ))),
                None => Ok(()),
            }
        })
    }

    /// `A`, `B` of the step from knot `k` with `(x, u)` that is known to end at `x2` with the
    /// multipliers `lambda` (a rollout's): the VI's derivatives at the converged step without
    /// taking it again (RK4 takes it: its derivatives come with the step).
    #[allow(clippy::too_many_arguments)]
    pub fn jacobians(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        x2: &mut [f64],
        lambda: &[f64],
        a: &mut DMatrix<f64>,
        bm: &mut DMatrix<f64>,
    ) -> Result<(), SimError> {
        // RK4's derivatives come with its step; the contact step's need its own solution
        // (its impulses, slacks and active rows), so a model with unilateral rows steps again.
        if !self.is_vi() || self.has_contacts() {
            return self.step(k, x, u, x2, Some((a, bm)));
        }
        a.as_mut_slice().fill(0.0);
        bm.as_mut_slice().fill(0.0);
        let dt = self.dt;
        let t2 = self.t0 + (k + 1) as f64 * dt;
        self.with_step(k, x, u, |method, cx, l, b| {
            let Stepper::Vi(vi) = method else {
                unreachable!("checked above")
            };
            // q₂: its dynamic part from x₂, its kinematic part where the step puts it.
            b.q2.copy_from(&b.q1);
            for (r, &i) in l.dynamic.iter().enumerate() {
                b.q2[i] = x2[r];
            }
            for &i in &l.kinematic {
                b.q2[i] = cx.motion.kinematic(i, t2)[0];
            }
            vi.lambda.as_mut_slice().copy_from_slice(lambda);
            vi.derivatives_into(cx, &b.q1, &b.p1, &b.q2, &mut b.first)?;
            read_jacobians(l, &b.first, a, bm);
            memory_jacobians(l, dt, a, bm);
            Ok(())
        })
    }

    /// The step's second derivatives from knot `k` with `(x, u)` contracted with `v` on
    /// `x₂` (DDP's `V_x'·f_xx` terms) into `hxx` (states²), `huu` (controls²) and `hux`
    /// (controls × states). The VI only; the memory is linear in `(x, u)`, so only `(q₂, p₂)`
    /// carry curvature. Takes the step first (`x2` receives it). `Ok(false)` with the three
    /// zero when the step went through contact, whose second derivatives are not formed:
    /// the Gauss–Newton model at that knot (docs/derivations.md §14).
    #[allow(clippy::too_many_arguments)]
    pub fn contracted(
        &mut self,
        k: usize,
        x: &[f64],
        u: &[f64],
        v: &[f64],
        x2: &mut [f64],
        hxx: &mut DMatrix<f64>,
        huu: &mut DMatrix<f64>,
        hux: &mut DMatrix<f64>,
    ) -> Result<bool, SimError> {
        if !self.is_vi() {
            return Err(SimError::InvalidInput(
                "DDP needs the VI's second derivatives: use iLQR with RK4".into(),
            ));
        }
        self.step(k, x, u, x2, None)?;
        if matches!(&self.method, Stepper::Vi(vi) if vi.through_contact()) {
            for h in [hxx, huu, hux] {
                h.as_mut_slice().fill(0.0);
            }
            return Ok(false);
        }
        let (n, inputs) = (self.sys.dof(), self.sys.input_count());
        self.with_step(k, x, u, |method, cx, l, b| {
            let Stepper::Vi(vi) = method else {
                unreachable!("checked above")
            };
            let nd = l.dynamic.len();
            b.covector.q2.copy_from_slice(&v[..nd]);
            b.covector.p2.copy_from_slice(&v[nd..2 * nd]);
            vi.contracted_second_derivatives(cx, &b.q1, &b.p1, &b.q2, &b.covector, &mut b.hessian)?;
            let at = |col: StepColumn| col.index(n, nd, inputs);
            hxx.as_mut_slice().fill(0.0);
            hux.as_mut_slice().fill(0.0);
            for (r, row) in l.x_column.iter().enumerate() {
                let Some(row) = *row else { continue };
                for (c, col) in l.x_column.iter().enumerate() {
                    if let Some(col) = *col {
                        hxx[(r, c)] = b.hessian[(at(row), at(col))];
                    }
                }
            }
            for (a, &ua) in l.u_column.iter().enumerate() {
                for (c, &ub) in l.u_column.iter().enumerate() {
                    huu[(a, c)] = b.hessian[(at(ua), at(ub))];
                }
                for (c, col) in l.x_column.iter().enumerate() {
                    if let Some(col) = *col {
                        hux[(a, c)] = b.hessian[(at(ua), at(col))];
                    }
                }
            }
            Ok(true)
        })
    }

    /// Whether the model has unilateral rows the VI holds (limits, contacts, slack strings).
    pub fn has_contacts(&self) -> bool {
        matches!(&self.method, Stepper::Vi(vi) if vi.has_contacts())
    }

    /// Lets a VI step that Newton cannot take be retried in up to `2^max` shorter steps, as a
    /// simulation does — for a plant that is stepped, not differentiated (a subdivided step's
    /// derivatives are not one step's, so a planner's steps are never subdivided).
    pub fn with_subdivisions(mut self, max: usize) -> Self {
        if let Stepper::Vi(vi) = &mut self.method {
            let settings = ViSettings {
                max_subdivisions: max,
                ..vi.settings
            };
            **vi = MidpointVi::new(&self.sys, settings);
        }
        self
    }

    /// Sets the contacts' relaxation `κ` of the VI's steps (`φγ = κ`, m·N·s; 0: hard).
    pub fn set_kappa(&mut self, kappa: f64) -> Result<(), SimError> {
        if !(kappa.is_finite() && kappa >= 0.0) {
            return Err(SimError::InvalidInput(format!(
                "the contacts' relaxation κ must be finite and not negative, got {kappa}"
            )));
        }
        if let Stepper::Vi(vi) = &mut self.method {
            vi.settings.kappa = kappa;
        }
        Ok(())
    }

    /// The deepest penetration of a unilateral row at the end of the last step (0 without).
    pub fn penetration(&self) -> f64 {
        match &self.method {
            Stepper::Vi(vi) => vi.penetration,
            Stepper::Rk4(_) => 0.0,
        }
    }

    /// How many dynamic variables the state's configuration part `q_d` holds (its first
    /// entries).
    pub fn dynamic_count(&self) -> usize {
        self.layout.dynamic.len()
    }

    /// The contacts' relaxation `κ` of the VI's steps (0 for RK4).
    pub fn kappa(&self) -> f64 {
        match &self.method {
            Stepper::Vi(vi) => vi.settings.kappa,
            Stepper::Rk4(_) => 0.0,
        }
    }
}

/// `A`, `B`'s `(q₂, p₂)` rows from the step's derivatives: each column the step input it is.
fn read_jacobians(l: &Layout, d: &StepDerivatives, a: &mut DMatrix<f64>, bm: &mut DMatrix<f64>) {
    let nd = l.dynamic.len();
    let read = |m: &mut DMatrix<f64>, c: usize, col: StepColumn| {
        let (by, j) = col.block();
        let (dq2, dp2) = (d.block(StepOutput::Q2, by), d.block(StepOutput::P2, by));
        for r in 0..nd {
            m[(r, c)] = dq2[(r, j)];
            m[(nd + r, c)] = dp2[(r, j)];
        }
    };
    for (c, col) in l.x_column.iter().enumerate() {
        if let Some(col) = *col {
            read(a, c, col);
        }
    }
    for (c, &col) in l.u_column.iter().enumerate() {
        read(bm, c, col);
    }
}

/// `A`, `B`'s memory rows: an input remembers itself, a kinematic control its value and
/// velocity `(ρ − c)/Δt`.
fn memory_jacobians(l: &Layout, dt: f64, a: &mut DMatrix<f64>, bm: &mut DMatrix<f64>) {
    for (c, control) in l.controls.iter().enumerate() {
        let Some(at) = l.memory[c] else { continue };
        bm[(at, c)] = 1.0;
        if let Control::Kinematic(_) = control {
            bm[(at + 1, c)] = 1.0 / dt;
            a[(at + 1, at)] = -1.0 / dt;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tree_model::{ContactSpec, ContactsSpec, GroundSpec};
    use tree_runtime::TreeSystem;

    /// The Solo-12 crouched on its four feet (μ = 0.8): the inputs that hold it through its
    /// contacts balance gravity with the feet's forces and keep it crouched for 0.2 s at hard
    /// contact, where the plain gravity compensation (each leg held up as if it hung) lets it
    /// fold within that time.
    #[test]
    fn a_crouched_quadruped_is_held_by_its_feet_and_its_motors() {
        let options = tree_model::UrdfOptions {
            floating_base: true,
            ..Default::default()
        };
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/solo12.urdf");
        let robot = tree_model::from_urdf_file(path, options).unwrap();
        let contacts = ["FL", "FR", "HL", "HR"].map(|leg| ContactSpec {
            frame: format!("{leg}_FOOT"),
            radius: Some(0.016),
            collide: Some(false),
            ..Default::default()
        });
        let spec = ContactsSpec {
            ground: Some(GroundSpec {
                friction: Some(0.8),
                ..Default::default()
            }),
            contacts: contacts.to_vec(),
            ..Default::default()
        };
        let model = robot.with_contacts(&spec).unwrap();
        let sys = TreeSystem::new(&model).unwrap();
        let controls = (0..12).map(Control::Input).collect();
        let mut d = DiscreteSystem::vi(sys, ViSettings::default(), 0.005, 0.0, controls).unwrap();
        let mut q0 = d.sys.zero_vector();
        let crouch = [
            0.0, 1.2, -2.4, 0.0, 1.2, -2.4, 0.0, -1.2, 2.4, 0.0, -1.2, 2.4,
        ];
        q0[2] = 0.1325;
        q0.as_mut_slice()[6..].copy_from_slice(&crouch);
        let dq0 = d.sys.zero_vector();
        // How far the crouch goes in 0.2 s under constant inputs `u`.
        let drift = |d: &mut DiscreteSystem<TreeSystem>, u: &DVector<f64>| {
            let mut x = d.state_of(&q0, &dq0, u.as_slice());
            let mut x2 = x.clone();
            let mut largest: f64 = 0.0;
            for k in 0..40 {
                d.step(k, x.as_slice(), u.as_slice(), x2.as_mut_slice(), None)
                    .unwrap();
                std::mem::swap(&mut x, &mut x2);
                for i in 0..18 {
                    largest = largest.max((x[i] - q0[i]).abs());
                }
            }
            largest
        };
        let (touching, _) = d.touching(&q0);
        assert_eq!(
            touching.len(),
            12,
            "four feet, each a gap and two tangent rows"
        );
        let held = d.holding_inputs(&q0);
        let g = d.generalized_gravity(&q0);
        let hanging = d.per_input(&g);
        let (kept, folded) = (drift(&mut d, &held), drift(&mut d, &hanging));
        println!("held: {kept:e}; gravity compensation: {folded:e}");
        assert!(
            kept < 1e-2 && folded > 0.5,
            "held: {kept} rad or m off the crouch; gravity compensation: {folded}"
        );
    }
}
