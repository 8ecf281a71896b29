//! The interpreted tree system: walks the validated model at run time with the composite
//! sweeps of [`tree_kernel::sweeps`] and the elements of [`tree_kernel::elements`] — the same code
//! `tree_model!` compiles.

mod added;

use std::sync::Arc;

use nalgebra::Dyn;
use tree_model::{Model, Motion};

use added::Added;
pub use added::{AddedTerms, Ask};

use crate::error::SimError;
use crate::system::{ConstraintTerms, Order, System, Terms, Vector};
use tree_kernel::articulated::{self, Articulated};
use tree_kernel::kernel::{self, Kernel};
use tree_kernel::se3::{Pose, Twist};
use tree_kernel::sweeps::{self, Reach, Workspace};
use tree_kernel::TreePlan;
use tree_kernel::{Dual, DualOutputs, Jet, JetOutputs, LANES};
use tree_kernel::{ElementForces, EnergySink, Lanes, WIDTH};

/// A frame's body velocity and, for each variable i that moves it, `(i, ∂v/∂q̇_i, ∂v/∂q_i)`.
pub(crate) type FrameVelocity = (Twist, Vec<(usize, Twist, Twist)>);

/// The interpreted system.
#[derive(Clone, Debug)]
pub struct TreeSystem {
    model: Model,
    /// Constant chains folded (as `tree_model!` compiles them).
    plan: TreePlan,
    kernel: Kernel<f64>,
    /// The same kernel over dual numbers, made on the first [`System::evaluate_dual`].
    dual_kernel: Option<Kernel<Dual>>,
    /// Every frame as modelled, for the poses.
    full_plan: TreePlan,
    constraint_names: Vec<String>,
    /// Per constraint row, the variables it depends on ([`TreePlan::constraint_variables`]).
    constraint_variables: Vec<Vec<usize>>,
    /// The articulated-body algorithm's storage, and its inputs' buffers.
    articulated: Articulated,
    kinematic: Vec<bool>,
    /// `!kinematic`: the columns a weighted constraint Hessian is formed on.
    dynamic: Vec<bool>,
    tau: Vec<f64>,
    /// The kernel over jets and the accelerations as jet constants, for
    /// [`System::inverse_dynamics_jet`] (made on first use).
    jet_kernel: Option<Box<Kernel<Jet<LANES>>>>,
    qdd_jet: Vec<Jet<LANES>>,
    /// The kernel and articulated-body storage over [`Lanes`], for the laned evaluations
    /// (made on first use).
    laned: Option<Box<Laned>>,
    /// A caller's terms added to the model's ([`TreeSystem::with_added`]).
    added: Option<Added>,
}

/// What the laned evaluations work in.
#[derive(Clone, Debug)]
struct Laned {
    kernel: Kernel<Lanes>,
    articulated: Articulated<Lanes>,
    tau: Vec<Lanes>,
}

/// An error when `model` would need more Jacobian columns than the runtime allocates (each
/// frame keeps one for every variable at or above it).
pub fn columns_fit(model: &Model) -> Result<(), SimError> {
    let (columns, deepest) = tree_kernel::column_count(model);
    if columns > tree_kernel::MAX_COLUMNS {
        return Err(SimError::InvalidInput(format!(
            "model `{}` would need {columns} Jacobian columns (each of its {} frames keeps one for every variable at or above it; its deepest frame has {deepest} variables above it); the interpreted system allocates at most {}",
            model.name,
            model.frames.len(),
            tree_kernel::MAX_COLUMNS
        )));
    }
    Ok(())
}

/// An error when `model`'s evaluation would not fit in memory.
fn memory_fits(model: &Model) -> Result<(), SimError> {
    let (columns, _) = tree_kernel::column_count(model);
    // Its dense matrices (M, ∂²L/∂q̇∂q, ∂²L/∂q², their factorisations and the integrators'
    // Newton matrices: about sixteen n × n) and the Jacobian columns' twists and their
    // derivatives (about a dozen numbers a column).
    let n = model.variables.len() as f64;
    let bytes = 8.0 * (16.0 * n * n + 12.0 * columns as f64);
    crate::memory::check(
        bytes,
        || format!("model `{}`'s {n} variables", model.name),
        "lock variables (--lock) to simulate a smaller model",
    )
}

/// [`kernel::elements_at`] (the outward sweep of the recursive dynamics, then the elements'
/// forces) compiled also for AVX2 and chosen at run time: wider registers and three-operand
/// instructions, no fused multiply-adds, so the same bits.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn dispatched_elements_at(
    plan: &TreePlan,
    k: &mut Kernel<f64>,
    q: &[f64],
    dq: &[f64],
    own: &mut Terms<Dyn>,
) {
    kernel::elements_at(plan, k, q, dq, own);
}

/// [`TreeSystem::articulated_acceleration`]'s evaluation over [`Lanes`] — the outward sweep
/// and the elements, `τ` completed by the model's own forces, the articulated-body step —
/// dispatched as [`dispatched_elements_at`] (for AVX2 the four lanes fill one register).
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn dispatched_lanes(
    plan: &TreePlan,
    laned: &mut Laned,
    kinematic: &[bool],
    (q, dq, tau): (&[Lanes], &[Lanes], &[Lanes]),
    qdd: &mut [Lanes],
    own: &mut ElementForces,
) {
    own.clear();
    kernel::elements_at(plan, &mut laned.kernel, q, dq, own);
    for (i, t) in laned.tau.iter_mut().enumerate() {
        *t = tau[i] + own.force[i] + own.dl_dq[i];
    }
    articulated::accelerations(
        plan,
        &laned.kernel.tree,
        &mut laned.articulated,
        dq,
        &laned.tau,
        kinematic,
        qdd,
    );
}

/// [`kernel::energy`] over [`Lanes`], dispatched as [`dispatched_lanes`].
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn dispatched_energy_lanes(
    plan: &TreePlan,
    kernel: &mut Kernel<Lanes>,
    q: &[Lanes],
    dq: &[Lanes],
) -> Lanes {
    let mut out = EnergySink::default();
    kernel::energy(plan, kernel, q, dq, &mut out);
    out.0
}

/// [`kernel::evaluate`] (the two sweeps, then the elements' terms), dispatched as
/// [`dispatched_elements_at`].
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+avx"))]
fn dispatched_evaluate(
    plan: &TreePlan,
    k: &mut Kernel<f64>,
    q: &[f64],
    dq: &[f64],
    order: Order,
    out: &mut Terms<Dyn>,
) {
    kernel::evaluate(plan, k, q, dq, order, out);
}

impl Laned {
    fn new(plan: &TreePlan) -> Self {
        Laned {
            kernel: Kernel::new(plan),
            articulated: Articulated::new(plan),
            tau: vec![Lanes::default(); plan.dof()],
        }
    }
}

impl TreeSystem {
    /// Builds the interpreted system for a validated model.
    pub fn new(model: &Model) -> Result<Self, SimError> {
        columns_fit(model)?;
        memory_fits(model)?;
        let plan = TreePlan::folded(model);
        Ok(TreeSystem {
            model: model.clone(),
            kernel: Kernel::new(&plan),
            dual_kernel: None,
            full_plan: TreePlan::new(model),
            constraint_names: model.constraint_row_names(),
            constraint_variables: plan.constraint_variables(),
            articulated: Articulated::new(&plan),
            kinematic: model.variables.iter().map(|v| v.is_kinematic()).collect(),
            dynamic: model.variables.iter().map(|v| !v.is_kinematic()).collect(),
            tau: vec![0.0; model.variables.len()],
            jet_kernel: None,
            qdd_jet: vec![Jet::default(); model.variables.len()],
            laned: None,
            added: None,
            plan,
        })
    }

    /// This system with `terms` added to the model's own on every evaluation (their
    /// constraint rows after the model's). Its fast paths that only know the model's terms
    /// (the articulated-body algorithm, lanes, jets) step aside, so every caller takes the
    /// general one, which asks for the added terms.
    pub fn with_added(mut self, terms: Arc<dyn AddedTerms>) -> Self {
        self.constraint_names = self.model.constraint_row_names();
        let first_row = self.constraint_names.len();
        self.constraint_names.extend(terms.constraint_names());
        let rows = self.constraint_names.len() - first_row;
        self.added = Some(Added {
            terms,
            first_row,
            rows,
        });
        self
    }

    /// Whether terms from outside the model were added ([`Self::with_added`]): a caller
    /// whose added terms call back into an interpreter may keep its lock for a short call.
    pub fn has_added(&self) -> bool {
        self.added.is_some()
    }

    /// The model this system was built from.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Every model frame's body velocity `v_k` (eq. (6)), without the columns
    /// [`Self::frame_velocities`] adds (allocates the result).
    pub fn body_velocities(&self, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Vec<Twist> {
        let mut out = vec![[0.0; 6]; self.model.frames.len()];
        sweeps::velocities(&self.full_plan, q.as_slice(), dq.as_slice(), &mut out);
        out
    }

    /// Every frame's body velocity `v_k` and its columns, one per model variable above it
    /// (a mimic frame's folded into its leader's, times the multiplier), for checking against
    /// finite differences (allocates; not for hot paths).
    pub fn frame_velocities(&mut self, q: &Vector<Dyn>, dq: &Vector<Dyn>) -> Vec<FrameVelocity> {
        let plan = &self.full_plan;
        let mut ws = Workspace::new(plan);
        let mut full = [vec![0.0; plan.full_dof()], vec![0.0; plan.full_dof()]];
        plan.extend(q.as_slice(), true, &mut full[0]);
        plan.extend(dq.as_slice(), false, &mut full[1]);
        sweeps::forward(plan, &mut ws, &full[0], &full[1], Reach::Everything);
        (0..plan.frames.len())
            .map(|k| {
                let f = &plan.frames[k];
                let mut cols: Vec<(usize, Twist, Twist)> = Vec::with_capacity(f.n);
                for a in 0..f.n {
                    let (i, m) = plan.reduced(plan.vars[f.var_start + a]);
                    let (jac, dv) = (ws.jac[f.col_offset + a], ws.dv_dq[f.col_offset + a]);
                    let at = match cols.iter().position(|c| c.0 == i) {
                        Some(at) => at,
                        None => {
                            cols.push((i, [0.0; 6], [0.0; 6]));
                            cols.len() - 1
                        }
                    };
                    for r in 0..6 {
                        cols[at].1[r] += m * jac[r];
                        cols[at].2[r] += m * dv[r];
                    }
                }
                (ws.velocity[k], cols)
            })
            .collect()
    }
}

impl System for TreeSystem {
    type N = Dyn;

    crate::system::described_by_model!();

    fn motion(&self, i: usize) -> Option<Motion> {
        self.model.variables[i].motion.clone()
    }

    fn is_kinematic(&self, i: usize) -> bool {
        self.model.variables[i].is_kinematic()
    }

    fn constraint_count(&self) -> usize {
        self.constraint_names.len()
    }

    fn constraint_name(&self, r: usize) -> &str {
        &self.constraint_names[r]
    }

    fn constraint_variables(&self, r: usize) -> Option<&[usize]> {
        self.constraint_variables.get(r).map(Vec::as_slice)
    }

    fn constraints(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        order: Order,
        out: &mut ConstraintTerms,
    ) {
        out.clear(order);
        kernel::constraints(
            &self.plan,
            &mut self.kernel,
            q.as_slice(),
            dq.as_slice(),
            order,
            out,
        );
        if let Some(added) = &self.added {
            added.add(Ask::Constraints(order), q.as_slice(), dq.as_slice(), out);
        }
    }

    fn weighted_constraint_hessian(
        &mut self,
        q: &Vector<Dyn>,
        weights: &[f64],
        out: &mut ConstraintTerms,
    ) {
        out.weigh(weights, true);
        let q = q.as_slice();
        kernel::weighted_constraint_hessian(
            &self.plan,
            &mut self.kernel,
            q,
            q,
            weights,
            &self.dynamic,
            out,
        );
        if let Some(added) = &self.added {
            added.add_weighted(q, weights, &self.dynamic, out);
        }
    }

    fn unilateral(&self) -> Vec<tree_model::Gap> {
        self.model.gaps()
    }

    fn gaps(&mut self, q: &Vector<Dyn>, weights: Option<&[f64]>, out: &mut ConstraintTerms) {
        let (plan, kernel, q) = (&self.plan, &mut self.kernel, q.as_slice());
        match weights {
            None => {
                out.clear(Order::First);
                kernel::gaps(plan, kernel, q, Order::First, out);
            }
            Some(w) => {
                out.weigh(w, true);
                kernel::weighted_gap_hessian(plan, kernel, q, w, &self.dynamic, out);
            }
        }
    }

    fn lagrangian(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        order: Order,
        out: &mut Terms<Dyn>,
    ) {
        out.clear(order);
        dispatched_evaluate(
            &self.plan,
            &mut self.kernel,
            q.as_slice(),
            dq.as_slice(),
            order,
            out,
        );
        if let Some(added) = &self.added {
            added.add(Ask::Terms(order), q.as_slice(), dq.as_slice(), out);
        }
    }

    fn mass_matrix(&mut self, q: &Vector<Dyn>, out: &mut Terms<Dyn>) {
        out.clear(Order::Dynamics);
        kernel::mass(&self.plan, &mut self.kernel, q.as_slice(), out);
        if let Some(added) = &self.added {
            let rest = vec![0.0; q.len()];
            added.add(Ask::Lagrangian, q.as_slice(), &rest, out);
        }
    }

    fn energy(&mut self, q: &Vector<Dyn>, dq: &Vector<Dyn>, out: &mut Terms<Dyn>) -> f64 {
        let (q, dq) = (q.as_slice(), dq.as_slice());
        kernel::energy(&self.plan, &mut self.kernel, q, dq, out);
        if let Some(added) = &self.added {
            // The added terms are potentials: `E = T + V` gains `V = −L_added`.
            out.total_energy -= added.lagrangian(q, dq);
        }
        out.total_energy
    }

    fn articulated_acceleration(
        &mut self,
        q: &Vector<Dyn>,
        dq: &Vector<Dyn>,
        tau: &Vector<Dyn>,
        qdd: &mut Vector<Dyn>,
        own: &mut Terms<Dyn>,
    ) -> bool {
        if self.plan.rows > 0 || self.added.is_some() || !self.plan.followers.is_empty() {
            return false;
        }
        own.clear(Order::First);
        let (q, dq) = (q.as_slice(), dq.as_slice());
        dispatched_elements_at(&self.plan, &mut self.kernel, q, dq, own);
        for (i, t) in self.tau.iter_mut().enumerate() {
            *t = tau[i] + own.force[i] + own.dl_dq[i];
        }
        articulated::accelerations_checked(
            &self.plan,
            &self.kernel.tree,
            &mut self.articulated,
            dq,
            &self.tau,
            &self.kinematic,
            qdd.as_mut_slice(),
        )
    }

    fn has_lanes(&self) -> bool {
        self.plan.rows == 0
            && self.added.is_none()
            && articulated::resolvable(&self.plan, &self.kinematic)
    }

    fn articulated_acceleration_lanes(
        &mut self,
        q: &[Lanes],
        dq: &[Lanes],
        tau: &[Lanes],
        qdd: &mut [Lanes],
        own: &mut ElementForces,
    ) -> Option<[bool; WIDTH]> {
        if !self.has_lanes() {
            return None;
        }
        let plan = &self.plan;
        let laned = self.laned.get_or_insert_with(|| Box::new(Laned::new(plan)));
        dispatched_lanes(plan, laned, &self.kinematic, (q, dq, tau), qdd, own);
        let art = &laned.articulated;
        Some(std::array::from_fn(|lane| {
            articulated::pivots_hold(&self.kinematic, |i| {
                let k = plan.variable_frames[i].expect("a resolvable variable drives a frame");
                (art.pivot[k].0[lane], art.pivot_scale[k].0[lane])
            })
        }))
    }

    fn energy_lanes(&mut self, q: &[Lanes], dq: &[Lanes]) -> Option<Lanes> {
        if !self.has_lanes() {
            return None;
        }
        let plan = &self.plan;
        let laned = self.laned.get_or_insert_with(|| Box::new(Laned::new(plan)));
        Some(dispatched_energy_lanes(plan, &mut laned.kernel, q, dq))
    }

    fn poses(&mut self, q: &Vector<Dyn>, out: &mut [Pose]) {
        sweeps::poses(&self.full_plan, q.as_slice(), out);
    }

    fn evaluate_dual(&mut self, q: &[Dual], dq: &[Dual], order: Order, out: &mut DualOutputs) {
        out.clear_lagrangian(order);
        out.clear_constraints(order);
        let plan = &self.plan;
        let kernel = self.dual_kernel.get_or_insert_with(|| Kernel::new(plan));
        kernel::evaluate(plan, kernel, q, dq, order, out);
        kernel::constraints(plan, kernel, q, dq, order, out);
        if let Some(added) = &self.added {
            added.add(Ask::Terms(order), q, dq, out);
            added.add(Ask::Constraints(order), q, dq, out);
        }
    }

    fn constraints_dual(&mut self, q: &[Dual], dq: &[Dual], order: Order, out: &mut DualOutputs) {
        out.clear_constraints(order);
        let plan = &self.plan;
        let kernel = self.dual_kernel.get_or_insert_with(|| Kernel::new(plan));
        kernel::constraints(plan, kernel, q, dq, order, out);
        if let Some(added) = &self.added {
            added.add(Ask::Constraints(order), q, dq, out);
        }
    }

    fn weighted_constraint_hessian_dual(
        &mut self,
        q: &[Dual],
        weights: &[Dual],
        out: &mut DualOutputs,
    ) {
        out.weigh(weights);
        let plan = &self.plan;
        let kernel = self.dual_kernel.get_or_insert_with(|| Kernel::new(plan));
        kernel::weighted_constraint_hessian(plan, kernel, q, q, weights, &self.dynamic, out);
        if let Some(added) = &self.added {
            added.add_weighted(q, weights, &self.dynamic, out);
        }
    }

    fn inverse_dynamics_jet(
        &mut self,
        q: &[Jet<LANES>],
        dq: &[Jet<LANES>],
        qdd: &[f64],
        out: &mut JetOutputs<LANES>,
    ) -> bool {
        if self.added.is_some() {
            return false;
        }
        out.clear();
        let plan = &self.plan;
        let kernel = self
            .jet_kernel
            .get_or_insert_with(|| Box::new(Kernel::new(plan)));
        for (x, &a) in self.qdd_jet.iter_mut().zip(qdd) {
            *x = Jet::constant(a);
        }
        kernel::inverse_dynamics(plan, kernel, q, dq, &self.qdd_jet, out);
        if plan.rows > 0 {
            kernel::constraints(plan, kernel, q, dq, Order::Dynamics, out);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The system's accelerations (its outward sweep and articulated-body step dispatched to
    /// AVX2 where the CPU has it) carry the generic bodies' bits.
    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    fn wave(n: usize, s: f64, scale: f64) -> Vector<Dyn> {
        Vector::<Dyn>::from_fn(n, |i, _| scale * (1.3 * i as f64 + s).sin())
    }

    /// The damped humanoid and the 8-link chain, each at a state away from zero.
    fn models_and_states() -> Vec<(Model, Vector<Dyn>, Vector<Dyn>)> {
        let humanoid = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.toml");
        [
            tree_model::from_toml_file(humanoid).expect("the humanoid loads"),
            tree_model::n_link_pendulum(8),
        ]
        .into_iter()
        .map(|m| {
            let n = m.variables.len();
            (m, wave(n, 0.2, 1.0), wave(n, 0.9, 2.0))
        })
        .collect()
    }

    #[test]
    fn the_dispatched_accelerations_give_the_generic_bits() {
        for (model, q, dq) in models_and_states() {
            let mut sys = TreeSystem::new(&model).expect("the system builds");
            let n = model.variables.len();
            let tau = wave(n, 1.7, 1.0);
            let mut own = Terms::zeros(Dyn(n));
            let mut qdd = Vector::<Dyn>::zeros(n);
            assert!(sys.articulated_acceleration(&q, &dq, &tau, &mut qdd, &mut own));
            // The generic bodies, compiled for the baseline CPU.
            let plan = TreePlan::folded(&model);
            let mut k = Kernel::<f64>::new(&plan);
            let mut generic = Terms::zeros(Dyn(n));
            generic.clear(Order::First);
            kernel::elements_at(&plan, &mut k, q.as_slice(), dq.as_slice(), &mut generic);
            let tau: Vec<f64> = (0..n)
                .map(|i| tau[i] + generic.force[i] + generic.dl_dq[i])
                .collect();
            let mut art = Articulated::new(&plan);
            let mut expected = vec![0.0; n];
            articulated::accelerations(
                &plan,
                &k.tree,
                &mut art,
                dq.as_slice(),
                &tau,
                &sys.kinematic,
                &mut expected,
            );
            assert_eq!(bits(qdd.as_slice()), bits(&expected), "{}", model.name);
        }
    }

    /// Four states in the lanes of one evaluation give each state's own bits: the
    /// accelerations, the model's own forces and the energy.
    #[test]
    fn the_laned_evaluations_give_each_states_bits() {
        for (model, _, _) in models_and_states() {
            let mut sys = TreeSystem::new(&model).expect("the system builds");
            let n = model.variables.len();
            let states: Vec<[Vector<Dyn>; 3]> = (0..WIDTH)
                .map(|l| {
                    let s = 0.4 * l as f64;
                    [
                        wave(n, s, 1.0),
                        wave(n, s + 0.9, 2.0),
                        wave(n, s + 1.7, 1.0),
                    ]
                })
                .collect();
            let lanes = |k: usize| -> Vec<Lanes> {
                (0..n)
                    .map(|i| Lanes(std::array::from_fn(|l| states[l][k][i])))
                    .collect()
            };
            let (q, dq, tau) = (lanes(0), lanes(1), lanes(2));
            let mut qdd = vec![Lanes::default(); n];
            let mut own = ElementForces::zeros(n);
            let held = sys
                .articulated_acceleration_lanes(&q, &dq, &tau, &mut qdd, &mut own)
                .expect("a model without constraints has the laned evaluation");
            assert_eq!(held, [true; WIDTH]);
            let energy = sys.energy_lanes(&q, &dq).expect("and the laned energy");
            for (l, [q, dq, tau]) in states.iter().enumerate() {
                let mut terms = Terms::zeros(Dyn(n));
                let mut alone = Vector::<Dyn>::zeros(n);
                assert!(sys.articulated_acceleration(q, dq, tau, &mut alone, &mut terms));
                let lane = |v: &[Lanes]| v.iter().map(|x| x.0[l]).collect::<Vec<_>>();
                assert_eq!(bits(&lane(&qdd)), bits(alone.as_slice()), "{}", model.name);
                assert_eq!(bits(&lane(&own.force)), bits(terms.force.as_slice()));
                let e = sys.energy(q, dq, &mut terms);
                assert_eq!(energy.0[l].to_bits(), e.to_bits(), "{}", model.name);
            }
            // The model's damping acts (the humanoid's), so the forces were compared.
            assert_eq!(
                own.force.iter().any(|f| f.0 != [0.0; WIDTH]),
                model.name != "pendulum-8",
                "{}",
                model.name
            );
        }
    }

    /// The system's Lagrangian terms (its two sweeps dispatched to AVX2 where the CPU has it)
    /// carry the generic bodies' bits, every term of a full evaluation.
    #[test]
    fn the_dispatched_evaluation_gives_the_generic_bits() {
        for (model, q, dq) in models_and_states() {
            let mut sys = TreeSystem::new(&model).expect("the system builds");
            let n = model.variables.len();
            let mut terms = Terms::zeros(Dyn(n));
            sys.lagrangian(&q, &dq, Order::Full, &mut terms);
            let plan = TreePlan::folded(&model);
            let mut k = Kernel::<f64>::new(&plan);
            let mut generic = Terms::zeros(Dyn(n));
            generic.clear(Order::Full);
            kernel::evaluate(
                &plan,
                &mut k,
                q.as_slice(),
                dq.as_slice(),
                Order::Full,
                &mut generic,
            );
            let every = |t: &Terms<Dyn>| {
                let mut v = vec![t.l];
                for m in [&t.dl_dq, &t.dl_ddq, &t.force] {
                    v.extend(m.iter());
                }
                for m in [&t.mass, &t.d2l_ddq_dq, &t.d2l_dq_dq] {
                    v.extend(m.iter());
                }
                v
            };
            assert!(every(&terms).iter().any(|&x| x != 0.0));
            assert_eq!(
                bits(&every(&terms)),
                bits(&every(&generic)),
                "{}",
                model.name
            );
        }
    }
}
