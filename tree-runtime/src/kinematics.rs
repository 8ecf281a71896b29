//! Frame kinematics: every frame's pose, Jacobian, velocity and acceleration, and the centre
//! of mass with its Jacobian — what Pinocchio's `forwardKinematics`, `getFrameJacobian`,
//! `getFrameVelocity`, `getFrameAcceleration`, `getFrameClassicalAcceleration`,
//! `centerOfMass` and `jacobianCenterOfMass` give, for any model (its compiled system too:
//! this reads the model, not the system).
//!
//! One outward sweep ([`tree_kernel::sweeps::forward`] over every model frame) gives each frame's
//! pose `g_k`, body twist `v_k` (eq. (6)) and body Jacobian columns `∂v_k/∂q̇_a` (eq. (7));
//! the body acceleration follows outward as in the articulated-body algorithm,
//! `a_k = Ad_{g_k⁻¹} a_par + (∂v_k/∂q_k) q̇_k + ξ_k q̈_k` from a base at rest
//! (docs/derivations.md §11). Twists are `(v, ω)`, linear part first, as Pinocchio's motions.
//! A twist `x` in frame `k`'s axes is reported in one of three [`Reference`]s:
//! * [`Reference::Local`]: `x` itself (the body twist);
//! * [`Reference::LocalWorldAligned`]: `(R v, R ω)` — the frame origin's velocity and the
//!   angular velocity in world axes;
//! * [`Reference::World`]: `Ad_{g_k} x = (R v + p × R ω, R ω)` (the spatial twist).
//!
//! ```
//! use tree_runtime::kinematics::{Kinematics, Reference};
//! let model = tree_runtime::tree_model::from_toml_str(
//!     r#"
//!     name = "arm"
//!     [[frame]]
//!     name = "shoulder"
//!     parent = "world"
//!     rz = "q"
//!     [[frame]]
//!     name = "hand"
//!     parent = "shoulder"
//!     tx = 0.5
//!     mass = 1.0
//!     "#,
//!     None,
//! )
//! .unwrap();
//! let mut k = Kinematics::new(&model).unwrap();
//! let hand = k.frame("hand").unwrap();
//! k.update(&[0.0], Some(&[2.0]), None).unwrap();
//! // The hand moves at 0.5 m × 2 rad/s along world y.
//! let v = k.velocity(hand, Reference::LocalWorldAligned);
//! assert!((v[1] - 1.0).abs() < 1e-15);
//! // Its Jacobian column is that velocity per unit q̇.
//! assert!((k.jacobian(hand, Reference::LocalWorldAligned)[(1, 0)] - 0.5).abs() < 1e-15);
//! ```

use nalgebra::DMatrix;
use tree_model::Model;

use crate::error::SimError;
use tree_kernel::articulated::outward_acceleration;
use tree_kernel::se3::{cross, zero6, Pose, Twist};
use tree_kernel::sweeps::{forward, Reach, Workspace};
use tree_kernel::{Body, TreePlan};

/// The axes and the point a frame's twist, Jacobian or acceleration is reported in (as
/// Pinocchio's `ReferenceFrame`; see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Reference {
    /// The frame's own axes, at its origin (the body twist).
    Local,
    /// World axes, at the frame's origin.
    #[default]
    LocalWorldAligned,
    /// World axes, at the world origin (the spatial twist).
    World,
}

impl Reference {
    /// The reference named `name` (`local`, `local_world_aligned`, `world`, any case).
    pub fn parse(name: &str) -> Option<Reference> {
        match name.to_ascii_lowercase().as_str() {
            "local" => Some(Reference::Local),
            "local_world_aligned" => Some(Reference::LocalWorldAligned),
            "world" => Some(Reference::World),
            _ => None,
        }
    }

    /// `x`, a twist in the axes of the frame at `pose`, in this reference.
    pub(crate) fn express(self, pose: &Pose, x: &Twist) -> Twist {
        if self == Reference::Local {
            return *x;
        }
        let v = pose.rotate(&[x[0], x[1], x[2]]);
        let w = pose.rotate(&[x[3], x[4], x[5]]);
        let v = match self {
            Reference::World => {
                let pw = cross(&pose.p, &w);
                [v[0] + pw[0], v[1] + pw[1], v[2] + pw[2]]
            }
            _ => v,
        };
        [v[0], v[1], v[2], w[0], w[1], w[2]]
    }
}

/// The centre of mass of the whole model and its motion, in world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CenterOfMass {
    /// The model's total mass.
    pub mass: f64,
    /// Its position `c = Σ m_b c_b / m`.
    pub position: [f64; 3],
    /// `ċ`.
    pub velocity: [f64; 3],
    /// `c̈`.
    pub acceleration: [f64; 3],
}

/// The kinematics of every frame of one model at one state (see the module documentation):
/// set the state with [`Self::update`], then read any frame. Nothing is allocated after
/// [`Self::new`] but the matrices the `jacobian` methods return (their `_into` forms
/// allocate nothing).
#[derive(Clone, Debug)]
pub struct Kinematics {
    plan: TreePlan,
    /// The frames' names, and the variables' (for errors).
    names: Vec<String>,
    variables: Vec<String>,
    ws: Workspace<f64>,
    /// Each frame's body acceleration `a_k` (in its axes).
    acceleration: Vec<Twist>,
    /// The state's q, q̇ and q̈ in full coordinates (a mimic frame's after the model's
    /// variables, [`TreePlan::extend`]).
    q: Vec<f64>,
    dq: Vec<f64>,
    ddq: Vec<f64>,
}

impl Kinematics {
    /// The kinematics of `model`'s frames (at every variable zero until [`Self::update`]).
    /// Fails as [`crate::TreeSystem::new`] does when the model would need more Jacobian
    /// columns than the runtime allocates.
    pub fn new(model: &Model) -> Result<Self, SimError> {
        crate::interpreted::columns_fit(model)?;
        let plan = TreePlan::new(model);
        let n = model.variables.len();
        let mut k = Kinematics {
            ws: Workspace::new(&plan),
            acceleration: vec![zero6(); plan.frames.len()],
            names: model.frames.iter().map(|f| f.name.clone()).collect(),
            variables: model.variables.iter().map(|v| v.name.clone()).collect(),
            q: vec![0.0; plan.full_dof()],
            dq: vec![0.0; plan.full_dof()],
            ddq: vec![0.0; plan.full_dof()],
            plan,
        };
        k.update(&vec![0.0; n], None, None)?;
        Ok(k)
    }

    /// The index of the frame named `name`; an error naming the model's frames otherwise.
    pub fn frame(&self, name: &str) -> Result<usize, SimError> {
        self.names.iter().position(|f| f == name).ok_or_else(|| {
            SimError::InvalidInput(format!(
                "there is no frame `{name}`; the frames are {}",
                self.names
                    .iter()
                    .map(|f| format!("`{f}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
    }

    /// The number of variables (the Jacobians' columns).
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// Sets the state: every variable's `q`, and `q̇`, `q̈` (zero when `None`), kinematic
    /// variables included. Errors when a length is not the number of variables or an entry
    /// is not finite.
    pub fn update(
        &mut self,
        q: &[f64],
        dq: Option<&[f64]>,
        ddq: Option<&[f64]>,
    ) -> Result<(), SimError> {
        let n = self.dof();
        for (what, x) in [("q", Some(q)), ("q̇", dq), ("q̈", ddq)] {
            let Some(x) = x else { continue };
            if x.len() != n {
                return Err(SimError::InvalidInput(format!(
                    "{what} has {}; the model has {}",
                    tree_model::Counted(x.len(), "entry"),
                    tree_model::Counted(n, "variable")
                )));
            }
            if let Some(i) = x.iter().position(|x| !x.is_finite()) {
                return Err(SimError::InvalidInput(format!(
                    "{what}'s entry {i} (`{}`) is {}, not a finite number",
                    self.variables[i], x[i]
                )));
            }
        }
        self.set(q, dq, ddq);
        Ok(())
    }

    /// [`Self::update`] for a state known to fit (the right lengths, finite): the task costs'
    /// per-knot call, whose states the solver made. Panics on a wrong length.
    #[doc(hidden)]
    pub fn set(&mut self, q: &[f64], dq: Option<&[f64]>, ddq: Option<&[f64]>) {
        self.plan.extend(q, true, &mut self.q);
        match dq {
            Some(x) => self.plan.extend(x, false, &mut self.dq),
            None => self.dq.as_mut_slice().fill(0.0),
        }
        match ddq {
            Some(x) => self.plan.extend(x, false, &mut self.ddq),
            None => self.ddq.as_mut_slice().fill(0.0),
        }
        forward(
            &self.plan,
            &mut self.ws,
            &self.q,
            &self.dq,
            Reach::Everything,
        );
        if dq.is_none() && ddq.is_none() {
            // At rest every frame's acceleration is zero.
            self.acceleration.fill(zero6());
        } else {
            self.accelerations();
        }
    }

    /// `a_k = Ad_{g_k⁻¹} a_par + c_k + ξ_k q̈_k` outward from a base at rest, with
    /// `c_k = (∂v_k/∂q_k) q̇_k` (docs/derivations.md §11): Newton–Euler's outward pass.
    fn accelerations(&mut self) {
        for k in 0..self.plan.frames.len() {
            let (plan, ws, acc) = (&self.plan, &self.ws, &self.acceleration);
            self.acceleration[k] =
                outward_acceleration(plan, ws, k, acc, zero6(), &self.dq, &self.ddq);
        }
    }

    /// Frame `f`'s pose in the world.
    pub fn pose(&self, f: usize) -> Pose {
        self.ws.pose[f]
    }

    /// Frame `f`'s twist in `reference`.
    pub fn velocity(&self, f: usize, reference: Reference) -> Twist {
        reference.express(&self.ws.pose[f], &self.ws.velocity[f])
    }

    /// Frame `f`'s spatial acceleration — the rate of change of its body twist — in
    /// `reference` (Pinocchio's `getFrameAcceleration`: not the acceleration of a point; see
    /// [`Self::classical_acceleration`]).
    pub fn acceleration(&self, f: usize, reference: Reference) -> Twist {
        reference.express(&self.ws.pose[f], &self.acceleration[f])
    }

    /// The acceleration of frame `f`'s origin in world axes, `R(a_v + ω × v)`.
    pub fn classical_acceleration(&self, f: usize) -> [f64; 3] {
        self.point_acceleration(f, &[0.0; 3])
    }

    /// The world acceleration of the point at `c` in frame `f`'s axes:
    /// `R(a_v + a_ω × c + ω × (v + ω × c))`.
    fn point_acceleration(&self, f: usize, c: &[f64; 3]) -> [f64; 3] {
        let (v, a) = (&self.ws.velocity[f], &self.acceleration[f]);
        let (lin, w) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
        let wc = cross(&w, c);
        let point_velocity = [lin[0] + wc[0], lin[1] + wc[1], lin[2] + wc[2]];
        let centripetal = cross(&w, &point_velocity);
        let tangential = cross(&[a[3], a[4], a[5]], c);
        let local: [f64; 3] = std::array::from_fn(|i| a[i] + tangential[i] + centripetal[i]);
        self.ws.pose[f].rotate(&local)
    }

    /// Frame `f`'s Jacobian in `reference`: 6 × (variables), linear rows first, so that
    /// [`Self::velocity`] is `J q̇`. Allocates the result; see [`Self::jacobian_into`].
    pub fn jacobian(&self, f: usize, reference: Reference) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(6, self.dof());
        self.jacobian_into(f, reference, &mut out);
        out
    }

    /// [`Self::jacobian`] into `out` (6 × variables).
    pub fn jacobian_into(&self, f: usize, reference: Reference, out: &mut DMatrix<f64>) {
        out.as_mut_slice().fill(0.0);
        let frame = &self.plan.frames[f];
        let pose = &self.ws.pose[f];
        for a in 0..frame.n {
            let (i, m) = self.plan.reduced(self.plan.vars[frame.var_start + a]);
            let column = reference.express(pose, &self.ws.jac[frame.col_offset + a]);
            for (r, x) in column.iter().enumerate() {
                out[(r, i)] += m * x;
            }
        }
    }

    /// The whole model's centre of mass and its velocity and acceleration; zeros when the
    /// model has no mass.
    pub fn center_of_mass(&self) -> CenterOfMass {
        let mut com = CenterOfMass {
            mass: 0.0,
            position: [0.0; 3],
            velocity: [0.0; 3],
            acceleration: [0.0; 3],
        };
        for (k, f) in self.plan.frames.iter().enumerate() {
            let Some((m, c)) = f.body.as_ref().map(mass_and_center) else {
                continue;
            };
            let pose = &self.ws.pose[k];
            let position = pose.rotate(&c);
            let v = &self.ws.velocity[k];
            let wc = cross(&[v[3], v[4], v[5]], &c);
            let velocity = pose.rotate(&[v[0] + wc[0], v[1] + wc[1], v[2] + wc[2]]);
            let acceleration = self.point_acceleration(k, &c);
            com.mass += m;
            for i in 0..3 {
                com.position[i] += m * (pose.p[i] + position[i]);
                com.velocity[i] += m * velocity[i];
                com.acceleration[i] += m * acceleration[i];
            }
        }
        if com.mass > 0.0 {
            for x in [&mut com.position, &mut com.velocity, &mut com.acceleration] {
                x.iter_mut().for_each(|x| *x /= com.mass);
            }
        }
        com
    }

    /// The centre of mass's Jacobian `∂c/∂q` (3 × variables; `ċ = J q̇`): the mass-weighted
    /// mean of each body's centre-of-mass point Jacobian `R(J_v + J_ω × c)`. Allocates the
    /// result.
    pub fn com_jacobian(&self) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(3, self.dof());
        self.com_jacobian_into(&mut out);
        out
    }

    /// [`Self::com_jacobian`] into `out` (3 × variables).
    pub(crate) fn com_jacobian_into(&self, out: &mut DMatrix<f64>) {
        out.as_mut_slice().fill(0.0);
        let mut total = 0.0;
        for (k, f) in self.plan.frames.iter().enumerate() {
            let Some((m, c)) = f.body.as_ref().map(mass_and_center) else {
                continue;
            };
            total += m;
            let pose = &self.ws.pose[k];
            for a in 0..f.n {
                let (i, factor) = self.plan.reduced(self.plan.vars[f.var_start + a]);
                let j = &self.ws.jac[f.col_offset + a];
                let wc = cross(&[j[3], j[4], j[5]], &c);
                let column = pose.rotate(&[j[0] + wc[0], j[1] + wc[1], j[2] + wc[2]]);
                for (r, x) in column.iter().enumerate() {
                    out[(r, i)] += factor * m * x;
                }
            }
        }
        if total > 0.0 {
            *out /= total;
        }
    }
}

/// A body's mass and centre of mass in its frame's axes.
fn mass_and_center(body: &Body) -> (f64, [f64; 3]) {
    match *body {
        Body::Principal { mass, .. } => (mass, [0.0; 3]),
        Body::Full { mass, com, .. } => (mass, com),
    }
}
