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

use super::cost::{Cost, Derivatives, Needs};
use super::discrete::Knot;
use super::frames::{frame_jacobians, log_so3, right_jacobian_inverse, world_poses};

/// A term with its targets placed in the world.
#[derive(Clone, Debug, PartialEq)]
enum Term {
    State {
        q_ref: DVector<f64>,
        dq_ref: DVector<f64>,
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
struct Residual {
    r: DVector<f64>,
    jx: DMatrix<f64>,
    ju: DMatrix<f64>,
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
}

impl TaskCost {
    /// The cost of `task` on `model`: offsets and default orientations are placed at the
    /// task's start configuration.
    pub fn new(task: &Task, model: &Model) -> Self {
        let start_poses = world_poses(model, &task.q0);
        let place = |t: &CostTerm| -> Term {
            match t {
                CostTerm::State {
                    q_ref,
                    dq_ref,
                    q_weight,
                    dq_weight,
                } => Term::State {
                    q_ref: DVector::from_column_slice(q_ref),
                    dq_ref: DVector::from_column_slice(dq_ref),
                    weight: DVector::from_iterator(
                        q_weight.len() + dq_weight.len(),
                        q_weight.iter().chain(dq_weight).copied(),
                    ),
                },
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
                        Target::Offset(o) => start_poses[*frame].1 + Vector3::from(*o),
                    },
                    weight: DVector::from_column_slice(weight),
                },
                CostTerm::Orientation {
                    frame,
                    target,
                    weight,
                } => Term::Orientation {
                    frame: *frame,
                    target: target
                        .map_or(start_poses[*frame].0, |r| Matrix3::from_fn(|i, j| r[i][j])),
                    weight: DVector::from_column_slice(weight),
                },
            }
        };
        TaskCost {
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
        }
    }

    /// Residual of `term` at `knot` (with `u` for running terms; `poses` every frame's
    /// world pose at the knot, when a term needs them).
    fn residual(
        &self,
        term: &Term,
        knot: &Knot,
        u: Option<&DVector<f64>>,
        poses: &[(Matrix3<f64>, Vector3<f64>)],
        jac: bool,
    ) -> Residual {
        let (nx, nu, n) = (knot.x.len(), self.controls.len(), knot.q.len());
        let zeros = |rows: usize| Residual {
            r: DVector::zeros(rows),
            jx: DMatrix::zeros(if jac { rows } else { 0 }, nx),
            ju: DMatrix::zeros(if jac { rows } else { 0 }, nu),
        };
        match term {
            Term::State { q_ref, dq_ref, .. } => {
                let mut res = zeros(2 * n);
                res.r.rows_mut(0, n).copy_from(&(&knot.q - q_ref));
                res.r.rows_mut(n, n).copy_from(&(&knot.dq - dq_ref));
                if jac {
                    res.jx.rows_mut(0, n).copy_from(&knot.q_x);
                    res.jx.rows_mut(n, n).copy_from(&knot.dq_x);
                }
                res
            }
            Term::Control { about, .. } => {
                let u = u.expect("a running term");
                let mut res = zeros(nu);
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
                res
            }
            Term::ControlRate { .. } => {
                let u = u.expect("a running term");
                let mut res = zeros(nu);
                for c in 0..nu {
                    res.r[c] = (u[c] - knot.previous[c]) / self.dt;
                    if jac {
                        res.ju[(c, c)] = 1.0 / self.dt;
                        res.jx[(c, knot.previous_at[c])] = -1.0 / self.dt;
                    }
                }
                res
            }
            Term::Frame { frame, target, .. } => {
                let mut res = zeros(3);
                res.r.copy_from(&(poses[*frame].1 - target));
                if jac {
                    let (jp, _) = frame_jacobians(&self.model, poses, *frame);
                    res.jx = jp * &knot.q_x;
                }
                res
            }
            Term::Orientation { frame, target, .. } => {
                let rf = poses[*frame].0;
                let phi = log_so3(&(target.transpose() * rf));
                let mut res = zeros(3);
                res.r.copy_from(&phi);
                if jac {
                    let (_, jw) = frame_jacobians(&self.model, poses, *frame);
                    let body = DMatrix::from_fn(3, 3, |i, j| rf[(j, i)]) * jw;
                    let jr = right_jacobian_inverse(&phi);
                    let jr = DMatrix::from_fn(3, 3, |i, j| jr[(i, j)]);
                    res.jx = jr * body * &knot.q_x;
                }
                res
            }
        }
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

    /// `Σ ½ w r²` over `terms` times `scale`, with derivatives into `d`.
    fn sum(
        &self,
        terms: &[Term],
        knot: &Knot,
        u: Option<&DVector<f64>>,
        scale: f64,
        d: Option<&mut Derivatives>,
    ) -> f64 {
        let jac = d.is_some();
        let mut d = d;
        if let Some(d) = d.as_mut() {
            d.lx.fill(0.0);
            d.lu.fill(0.0);
            d.lxx.fill(0.0);
            d.luu.fill(0.0);
            d.lux.fill(0.0);
        }
        let placed = terms
            .iter()
            .any(|t| matches!(t, Term::Frame { .. } | Term::Orientation { .. }));
        let poses = if placed {
            world_poses(&self.model, knot.q.as_slice())
        } else {
            Vec::new()
        };
        let mut total = 0.0;
        for term in terms {
            let w = Self::weight(term);
            let res = self.residual(term, knot, u, &poses, jac);
            let wr = res.r.component_mul(w) * scale;
            total += 0.5 * wr.dot(&res.r);
            if let Some(d) = d.as_mut() {
                let wjx = DMatrix::from_fn(res.jx.nrows(), res.jx.ncols(), |i, j| {
                    w[i] * scale * res.jx[(i, j)]
                });
                let wju = DMatrix::from_fn(res.ju.nrows(), res.ju.ncols(), |i, j| {
                    w[i] * scale * res.ju[(i, j)]
                });
                d.lx += res.jx.tr_mul(&wr);
                d.lu += res.ju.tr_mul(&wr);
                d.lxx += res.jx.tr_mul(&wjx);
                d.luu += res.ju.tr_mul(&wju);
                d.lux += res.ju.tr_mul(&wjx);
            }
        }
        total
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
        self.sum(&self.running, x, Some(u), self.dt, d)
    }

    fn terminal(&mut self, x: &Knot, d: Option<&mut Derivatives>) -> f64 {
        self.sum(&self.terminal, x, None, 1.0, d)
    }

    fn needs(&self) -> Needs {
        let all = || self.running.iter().chain(&self.terminal);
        let n = self.model.variables.len();
        Needs {
            velocity: all().any(|t| match t {
                Term::State { weight, .. } => weight.rows(n, n).iter().any(|w| *w != 0.0),
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
