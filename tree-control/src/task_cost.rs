//! The cost a task file states (README, "Optimal control"): a sum of terms `½ w |r|²` with
//! per-entry weights, running terms weighted by Δt, each residual `r` written on a [`Knot`]
//! with its exact Jacobian, and its Hessian taken as Gauss–Newton `Jᵀ W J` (as Crocoddyl
//! does). Residuals (docs/derivations.md §10):
//! * `state`: `(q − q_ref, q̇ − q̇_ref)`;
//! * `control`: `u − g(q)` (about gravity) or `u` on inputs, `ρ − ρ_start` on kinematic
//!   controls;
//! * `control_rate`: `(u_k − u_{k−1})/Δt`, the previous value from the state's memory;
//! * `frame`: `p_f(q) − target`;
//! * `orientation`: `log(R_targetᵀ R_f)`, whose Jacobian is `J_r⁻¹(r) R_fᵀ J_ω`.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use tree_model::{About, Control, CostTerm, Model, Target, Task};

use crate::cost::{Cost, Derivatives};
use crate::frames::{log_so3, right_jacobian_inverse};
use crate::knot::Knot;
use crate::knot::Needs;
use tree_kernel::se3::Pose;
use tree_runtime::kinematics::{Kinematics, Reference};
use tree_runtime::linalg::{mul_into, tr_mul_into, tr_mul_into_symmetric, Packing};
use tree_runtime::SimError;

/// A term with its targets placed in the world.
#[derive(Clone, Debug, PartialEq)]
enum Term {
    /// Only the entries of `(q, q̇)` with a non-zero weight (`entries`, indices into the
    /// stacked `(q, q̇)`): the others add nothing to the cost or its derivatives.
    State {
        q_ref: DVector<f64>,
        dq_ref: DVector<f64>,
        entries: Vec<usize>,
        weight: DVector<f64>,
    },
    Control {
        weight: DVector<f64>,
        about: About,
    },
    ControlRate {
        weight: DVector<f64>,
    },
    Frame {
        frame: usize,
        target: Vector3<f64>,
        weight: DVector<f64>,
    },
    Orientation {
        frame: usize,
        target: Matrix3<f64>,
        weight: DVector<f64>,
    },
}

/// One residual's value, Jacobians and weights, accumulated into a [`Derivatives`].
#[derive(Clone, Debug, Default)]
struct Residual {
    r: DVector<f64>,
    jx: DMatrix<f64>,
    ju: DMatrix<f64>,
    /// `s w ∘ r`, and the Jacobians' rows scaled by `s w` (for the Gauss–Newton terms).
    wr: DVector<f64>,
    wjx: DMatrix<f64>,
    wju: DMatrix<f64>,
}

impl Residual {
    /// Sized for `rows` rows over `nx` states and `nu` controls (allocates only when the
    /// shape changes: on the first knot).
    fn fit(&mut self, rows: usize, nx: usize, nu: usize) {
        if self.r.len() != rows || self.jx.ncols() != nx || self.ju.ncols() != nu {
            *self = Residual {
                r: DVector::zeros(rows),
                jx: DMatrix::zeros(rows, nx),
                ju: DMatrix::zeros(rows, nu),
                wr: DVector::zeros(rows),
                wjx: DMatrix::zeros(rows, nx),
                wju: DMatrix::zeros(rows, nu),
            };
        }
    }
}

/// What one evaluation works in, kept between knots: the frames' kinematics at the knot, a
/// frame's Jacobian (6 × n) and three of its rows (3 × n), and each term's residual.
#[derive(Clone, Debug)]
struct Scratch {
    frames: Kinematics,
    j6: DMatrix<f64>,
    jp: DMatrix<f64>,
    running: Vec<Residual>,
    terminal: Vec<Residual>,
    /// The factors of the dense products, packed.
    packing: Packing,
}

/// The cost of a [`Task`] on its model.
#[derive(Clone, Debug)]
pub struct TaskCost {
    model: Model,
    dt: f64,
    controls: Vec<Control>,
    /// Kinematic controls' start values (the `control` term's reference for them).
    start: DVector<f64>,
    running: Vec<Term>,
    terminal: Vec<Term>,
    /// A `control_rate` term reads inputs' previous values ([`Task::reads_previous_inputs`]).
    reads_previous_inputs: bool,
    scratch: Scratch,
}

impl TaskCost {
    /// The cost of `task` on `model`: offsets and default orientations are placed at the
    /// task's start configuration. Fails only as [`Kinematics::new`] does (a model too large
    /// for the runtime's Jacobian columns).
    pub fn new(task: &Task, model: &Model) -> Result<Self, SimError> {
        let mut frames = Kinematics::new(model)?;
        frames.update(&task.q0, None, None)?;
        let start = |f: usize| world(&frames.pose(f));
        let place = |t: &CostTerm| -> Term {
            match t {
                CostTerm::State {
                    q_ref,
                    dq_ref,
                    q_weight,
                    dq_weight,
                } => {
                    let stacked: Vec<f64> = q_weight.iter().chain(dq_weight).copied().collect();
                    let entries: Vec<usize> =
                        (0..stacked.len()).filter(|&i| stacked[i] != 0.0).collect();
                    Term::State {
                        q_ref: DVector::from_column_slice(q_ref),
                        dq_ref: DVector::from_column_slice(dq_ref),
                        weight: DVector::from_iterator(
                            entries.len(),
                            entries.iter().map(|&i| stacked[i]),
                        ),
                        entries,
                    }
                }
                CostTerm::Control { weight, about } => Term::Control {
                    weight: DVector::from_column_slice(weight),
                    about: *about,
                },
                CostTerm::ControlRate { weight } => Term::ControlRate {
                    weight: DVector::from_column_slice(weight),
                },
                CostTerm::Frame {
                    frame,
                    target,
                    weight,
                } => Term::Frame {
                    frame: *frame,
                    target: match target {
                        Target::World(p) => Vector3::from(*p),
                        Target::Offset(o) => start(*frame).1 + Vector3::from(*o),
                    },
                    weight: DVector::from_column_slice(weight),
                },
                CostTerm::Orientation {
                    frame,
                    target,
                    weight,
                } => Term::Orientation {
                    frame: *frame,
                    target: target.map_or(start(*frame).0, |r| Matrix3::from_fn(|i, j| r[i][j])),
                    weight: DVector::from_column_slice(weight),
                },
            }
        };
        let n = model.variables.len();
        Ok(TaskCost {
            model: model.clone(),
            dt: task.dt,
            start: DVector::from_iterator(
                task.controls.len(),
                task.controls.iter().map(|c| match c {
                    Control::Kinematic(i) => task.q0[*i],
                    Control::Input(_) => 0.0,
                }),
            ),
            controls: task.controls.clone(),
            running: task.running.iter().map(place).collect(),
            terminal: task.terminal.iter().map(place).collect(),
            reads_previous_inputs: task.reads_previous_inputs(),
            scratch: Scratch {
                frames,
                j6: DMatrix::zeros(6, n),
                jp: DMatrix::zeros(3, n),
                running: vec![Residual::default(); task.running.len()],
                terminal: vec![Residual::default(); task.terminal.len()],
                packing: Packing::default(),
            },
        })
    }

    fn weight(term: &Term) -> &DVector<f64> {
        match term {
            Term::State { weight, .. }
            | Term::Control { weight, .. }
            | Term::ControlRate { weight }
            | Term::Frame { weight, .. }
            | Term::Orientation { weight, .. } => weight,
        }
    }

    /// `Σ ½ s w r²` over the running (`u` given) or terminal terms, `s = scale`, with the
    /// Gauss–Newton derivatives into `d`; nothing allocated after the first knot.
    fn sum(
        &mut self,
        knot: &Knot,
        u: Option<&DVector<f64>>,
        scale: f64,
        d: Option<&mut Derivatives>,
    ) -> f64 {
        let Scratch {
            frames,
            j6,
            jp,
            running,
            terminal,
            packing,
        } = &mut self.scratch;
        let (terms, residuals) = match u {
            Some(_) => (&self.running, running),
            None => (&self.terminal, terminal),
        };
        let jac = d.is_some();
        let mut d = d;
        if let Some(d) = d.as_mut() {
            d.lx.as_mut_slice().fill(0.0);
            d.lu.as_mut_slice().fill(0.0);
            d.lxx.as_mut_slice().fill(0.0);
            d.luu.as_mut_slice().fill(0.0);
            d.lux.as_mut_slice().fill(0.0);
        }
        let placed = terms
            .iter()
            .any(|t| matches!(t, Term::Frame { .. } | Term::Orientation { .. }));
        if placed {
            frames.set(knot.q.as_slice(), None, None);
        }
        let at = At {
            controls: &self.controls,
            start: &self.start,
            dt: self.dt,
        };
        let mut total = 0.0;
        for (term, res) in terms.iter().zip(residuals.iter_mut()) {
            at.residual(
                term,
                knot,
                u,
                frames,
                jac,
                (&mut *j6, &mut *jp, &mut *packing),
                res,
            );
            let w = Self::weight(term);
            for i in 0..res.r.len() {
                res.wr[i] = scale * w[i] * res.r[i];
                total += 0.5 * res.wr[i] * res.r[i];
            }
            if let Some(d) = d.as_mut() {
                // Each row scaled by s w_i, walked column by column (the storage's order).
                let rows = res.r.len().max(1);
                for (scaled, jac) in [(&mut res.wjx, &res.jx), (&mut res.wju, &res.ju)] {
                    let columns = scaled.as_mut_slice().chunks_exact_mut(rows);
                    for (out, column) in columns.zip(jac.as_slice().chunks_exact(rows)) {
                        for ((o, &x), &wi) in out.iter_mut().zip(column).zip(w.as_slice()) {
                            *o = scale * wi * x;
                        }
                    }
                }
                d.lx.gemv_tr(1.0, &res.jx, &res.wr, 1.0);
                tr_mul_into_symmetric(&mut d.lxx, &res.jx, &res.wjx, 1.0, packing);
                // State, frame and orientation residuals do not read the controls.
                if matches!(term, Term::Control { .. } | Term::ControlRate { .. }) {
                    d.lu.gemv_tr(1.0, &res.ju, &res.wr, 1.0);
                    tr_mul_into_symmetric(&mut d.luu, &res.ju, &res.wju, 1.0, packing);
                    tr_mul_into(&mut d.lux, &res.ju, &res.wjx, 1.0, packing);
                }
            }
        }
        total
    }
}

/// A pose as a rotation matrix and a position.
fn world(pose: &Pose) -> (Matrix3<f64>, Vector3<f64>) {
    (Matrix3::from_fn(|i, j| pose.r[i][j]), Vector3::from(pose.p))
}

/// What a residual reads besides the knot.
struct At<'a> {
    controls: &'a [Control],
    start: &'a DVector<f64>,
    dt: f64,
}

impl At<'_> {
    /// Residual of `term` at `knot` into `res` (with `u` for running terms; `frames` the
    /// frames' kinematics at the knot, when a term needs them; `frame_jac` a 6 × n and a
    /// 3 × n buffer for a frame's Jacobian).
    #[allow(clippy::too_many_arguments)] // the term, where it is read, and its buffers
    fn residual(
        &self,
        term: &Term,
        knot: &Knot,
        u: Option<&DVector<f64>>,
        frames: &Kinematics,
        jac: bool,
        frame_jac: (&mut DMatrix<f64>, &mut DMatrix<f64>, &mut Packing),
        res: &mut Residual,
    ) {
        let (nx, nu, n) = (knot.x.len(), self.controls.len(), knot.q.len());
        let rows = match term {
            Term::State { entries, .. } => entries.len(),
            Term::Control { .. } | Term::ControlRate { .. } => nu,
            Term::Frame { .. } | Term::Orientation { .. } => 3,
        };
        res.fit(rows, nx, nu);
        if jac {
            // A state term's J_x is gathered whole below; every other term writes a few
            // entries of zeroed Jacobians.
            if !matches!(term, Term::State { .. }) {
                res.jx.as_mut_slice().fill(0.0);
            }
            res.ju.as_mut_slice().fill(0.0);
        }
        match term {
            Term::State {
                q_ref,
                dq_ref,
                entries,
                ..
            } => {
                for (k, &e) in entries.iter().enumerate() {
                    res.r[k] = if e < n {
                        knot.q[e] - q_ref[e]
                    } else {
                        knot.dq[e - n] - dq_ref[e - n]
                    };
                }
                // Row k of J_x is row e_k of q_x (or of q̇_x), gathered column by column.
                if jac && !entries.is_empty() {
                    let (q_x, dq_x) = (knot.q_x.as_slice(), knot.dq_x.as_slice());
                    let columns = res.jx.as_mut_slice().chunks_exact_mut(entries.len());
                    for (c, out) in columns.enumerate() {
                        let (q_c, dq_c) = (&q_x[c * n..(c + 1) * n], &dq_x[c * n..(c + 1) * n]);
                        for (o, &e) in out.iter_mut().zip(entries) {
                            *o = if e < n { q_c[e] } else { dq_c[e - n] };
                        }
                    }
                }
            }
            Term::Control { about, .. } => {
                let u = u.expect("a running term");
                for (c, control) in self.controls.iter().enumerate() {
                    res.r[c] = u[c]
                        - match (control, about) {
                            (Control::Kinematic(_), _) => self.start[c],
                            (Control::Input(_), About::Gravity) => knot.gravity[c],
                            (Control::Input(_), About::Zero) => 0.0,
                        };
                    if jac {
                        res.ju[(c, c)] = 1.0;
                        if let (Control::Input(_), About::Gravity) = (control, about) {
                            for col in 0..nx {
                                res.jx[(c, col)] = -knot.gravity_x[(c, col)];
                            }
                        }
                    }
                }
            }
            Term::ControlRate { .. } => {
                let u = u.expect("a running term");
                for c in 0..nu {
                    res.r[c] = (u[c] - knot.previous[c]) / self.dt;
                    if jac {
                        res.ju[(c, c)] = 1.0 / self.dt;
                        if let Some(at) = knot.previous_at[c] {
                            res.jx[(c, at)] = -1.0 / self.dt;
                        }
                    }
                }
            }
            Term::Frame { frame, target, .. } => {
                res.r.copy_from(&(world(&frames.pose(*frame)).1 - target));
                if jac {
                    // ∂p_f/∂q: the linear rows in world axes at the frame's origin.
                    let (j6, jp, packing) = frame_jac;
                    frames.jacobian_into(*frame, Reference::LocalWorldAligned, j6);
                    jp.copy_from(&j6.rows(0, 3));
                    mul_into(&mut res.jx, jp, &knot.q_x, 0.0, packing);
                }
            }
            Term::Orientation { frame, target, .. } => {
                let rf = world(&frames.pose(*frame)).0;
                let phi = log_so3(&(target.transpose() * rf));
                res.r.copy_from(&phi);
                if jac {
                    // J_r⁻¹(φ) R_fᵀ J_ω: the angular rows in the frame's own axes.
                    let (j6, jp, packing) = frame_jac;
                    frames.jacobian_into(*frame, Reference::Local, j6);
                    let m = right_jacobian_inverse(&phi);
                    for c in 0..n {
                        for i in 0..3 {
                            jp[(i, c)] = (0..3).map(|k| m[(i, k)] * j6[(3 + k, c)]).sum();
                        }
                    }
                    mul_into(&mut res.jx, jp, &knot.q_x, 0.0, packing);
                }
            }
        }
    }
}

impl Cost for TaskCost {
    fn running(
        &mut self,
        _k: usize,
        x: &Knot,
        u: &DVector<f64>,
        d: Option<&mut Derivatives>,
    ) -> f64 {
        let dt = self.dt;
        self.sum(x, Some(u), dt, d)
    }

    fn terminal(&mut self, x: &Knot, d: Option<&mut Derivatives>) -> f64 {
        self.sum(x, None, 1.0, d)
    }

    fn needs(&self) -> Needs {
        let all = || self.running.iter().chain(&self.terminal);
        let n = self.model.variables.len();
        Needs {
            velocity: all().any(|t| match t {
                Term::State { entries, .. } => entries.iter().any(|&e| e >= n),
                _ => false,
            }),
            gravity: all().any(|t| {
                matches!(
                    t,
                    Term::Control {
                        about: About::Gravity,
                        ..
                    }
                )
            }) && self.controls.iter().any(|c| matches!(c, Control::Input(_))),
            input_memory: self.reads_previous_inputs,
        }
    }

    fn check(&self, nx: usize, nu: usize) -> Result<(), String> {
        let _ = nx;
        if nu != self.controls.len() {
            return Err(format!(
                "the task has {} controls; the system was built with {nu}",
                self.controls.len()
            ));
        }
        Ok(())
    }
}
