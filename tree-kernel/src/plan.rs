//! The structure of a validated model as the recursions walk it: for each frame its parent,
//! primitive, parameter, the variables that move it, where its columns live, and whether
//! anything (a mass, a constraint, a spring, a damper) needs it. Built once; shared by the
//! interpreted system and the compiler.
//!
//! [`TreePlan::folded`] also folds constant transforms: a frame with a constant primitive that
//! nothing attaches to disappears into its children's `pre` transform, so a chain of constant
//! primitives costs one constant transform, and its body joins its kept ancestor's as one
//! composite rigid body (docs/derivations.md §4).

use tree_model::{
    Constraint, ConstraintKind, Damper, Gap, GapKind, Joint, Mass, Model, Parameter, PrimitiveKind,
    Spring, SpringKind,
};

use crate::scalar::Scalar;
use crate::se3::{ConstantTransform, LocalTransform, Pose, SpatialInertia};

/// A frame's rigid body as the inward sweep uses it, classified and prepared once.
// Kept inline (not boxed): one per frame, read by every inward sweep.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Body {
    /// The paper's body: at the frame origin, principal axes along the frame's.
    Principal {
        /// Mass.
        mass: f64,
        /// `(Ixx, Iyy, Izz)`.
        moments: [f64; 3],
    },
    /// Any other body: its spatial inertia at the frame origin (docs/derivations.md §2).
    Full {
        /// Mass.
        mass: f64,
        /// Centre of mass in the frame's axes.
        com: [f64; 3],
        /// `[[m 1, −m ĉ], [m ĉ, I_c − m ĉĉ]]`.
        inertia: SpatialInertia<f64>,
    },
}

impl Body {
    /// The body of `m`, or `None` when it has neither mass nor inertia.
    pub fn of(m: &Mass) -> Option<Body> {
        if !m.is_nonzero() {
            return None;
        }
        Some(match m.diagonal() {
            Some(moments) => Body::Principal {
                mass: m.mass,
                moments,
            },
            None => Body::Full {
                mass: m.mass,
                com: m.com,
                inertia: SpatialInertia::body(m.mass, &m.com, &m.inertia),
            },
        })
    }

    /// Its mass.
    pub fn mass(&self) -> f64 {
        match *self {
            Body::Principal { mass, .. } | Body::Full { mass, .. } => mass,
        }
    }

    /// Its mass, centre of mass and spatial inertia at the frame origin.
    fn parts(&self) -> (f64, [f64; 3], SpatialInertia<f64>) {
        match *self {
            Body::Principal { mass, moments } => {
                (mass, [0.0; 3], SpatialInertia::diagonal(mass, &moments))
            }
            Body::Full { mass, com, inertia } => (mass, com, inertia),
        }
    }

    /// The composite rigid body of `own` (this frame's body, if any) and `other`, carried
    /// rigidly at the constant pose `g` from this frame: the masses and the first mass
    /// moments `m c` add (`other`'s carried as the inward sweep carries a subtree's,
    /// `R h + m p`), and so do the spatial inertias once both are seen from this frame's
    /// origin (`Ad_{g⁻¹}ᵀ I Ad_{g⁻¹}`, docs/derivations.md §4).
    fn joined(own: Option<Body>, other: &Body, g: &Pose) -> Body {
        let (m_other, c_other, i_other) = other.parts();
        let mut moment = g.moment_to_parent(&c_other.map(|x| m_other * x), m_other);
        let mut inertia = g.inertia_to_parent(&i_other);
        let mut mass = m_other;
        if let Some(b) = own {
            let (m, c, i) = b.parts();
            mass += m;
            moment = [0, 1, 2].map(|a| moment[a] + m * c[a]);
            inertia.add(&i);
        }
        // A body with inertia but no mass has no centre of mass to weigh: any point will do.
        let com = if mass > 0.0 {
            moment.map(|h| h / mass)
        } else {
            [0.0; 3]
        };
        Body::Full { mass, com, inertia }
    }
}

/// One frame of the plan.
#[derive(Clone, Debug, PartialEq)]
pub struct FramePlan {
    /// Index of the parent frame (`None`: the world).
    pub parent: Option<usize>,
    /// A constant transform applied before the primitive (folded constant frames).
    pub(crate) pre: Option<ConstantTransform>,
    /// Its primitive.
    pub kind: PrimitiveKind,
    /// Its parameter.
    pub joint: Joint,
    /// The variables that move this frame, root first (own last when driven):
    /// `TreePlan::vars[var_start..var_start + n]`. A parent's list is a prefix of its child's.
    pub var_start: usize,
    /// Number of variables at or above this frame (its columns).
    pub n: usize,
    /// Offset of this frame's `n` columns (`∂v/∂q̇_i`, `∂v/∂q_i`) in the column buffers.
    pub col_offset: usize,
    /// Whether this frame or a descendant carries mass or has a spring or damper attached:
    /// the frames the Lagrangian's sweeps visit (constraints have their own reach,
    /// [`Self::leads_to_attached`]).
    pub needed: bool,
    /// A constraint, spring or damper attaches here: its world point Jacobian is computed.
    pub attached: bool,
    /// This frame or a descendant is [`Self::attached`]: the constraints' sweep visits it,
    /// and its `∂v/∂q̇` columns are needed at every order (the elements' point Jacobians are
    /// built from them).
    pub leads_to_attached: bool,
    /// This frame or a descendant has a spring or damper attached: the Lagrangian's sweep
    /// needs its `∂v/∂q̇` columns at every order.
    pub leads_to_element: bool,
    /// The rigid body this frame carries, if it has any mass or inertia.
    pub body: Option<Body>,
    /// Total mass of the subtree rooted here.
    pub subtree_mass: f64,
}

impl FramePlan {
    /// Position of the own variable in the ancestor list, when the frame is driven.
    pub fn own(&self) -> Option<usize> {
        matches!(self.joint, Joint::Variable(_)).then(|| self.n - 1)
    }
}

/// A model frame as the pose recursion (eq. (1)) needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseFrame {
    /// Index of the parent frame (`None`: the world).
    pub parent: Option<usize>,
    /// Its primitive.
    pub kind: PrimitiveKind,
    /// Its parameter.
    pub joint: Joint,
}

/// A variable the model does not have: a mimic frame's own parameter
/// `x = multiplier·q_leader + offset` (docs/derivations.md §12). The sweeps treat it as a
/// variable of its own, after the model's; [`crate::outputs::Contract`] takes what they
/// produce back to the model's variables.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Follower {
    /// The model variable it follows.
    pub leader: usize,
    /// `∂x/∂q_leader`.
    pub multiplier: f64,
    /// `x` at `q_leader = 0`.
    pub offset: f64,
}

/// The plan of a whole tree.
#[derive(Clone, Debug, PartialEq)]
pub struct TreePlan {
    /// The frames the sweeps walk: every model frame, or after folding only those that are
    /// driven or carry mass.
    pub frames: Vec<FramePlan>,
    /// Every model frame, for [`crate::sweeps::poses`].
    pub pose_frames: Vec<PoseFrame>,
    /// Concatenated ancestor-variable lists (in full coordinates: a mimic frame's variable
    /// is its [`Follower`]'s, numbered after the model's).
    pub vars: Vec<usize>,
    /// The frame each variable drives (`None`: a variable that moves no frame): the model's
    /// variables, then the followers.
    pub variable_frames: Vec<Option<usize>>,
    /// The mimic frames' variables, `dof() + k` in full coordinates.
    pub followers: Vec<Follower>,
    /// Gravity in world axes.
    pub gravity: [f64; 3],
    /// Total number of columns over all frames.
    pub columns: usize,
    /// Per-variable viscous damping `c_i` (the followers' after the model's).
    pub damping: Vec<f64>,
    /// The model's constraints, springs and dampers, their frames as indices into `frames`.
    pub constraints: Vec<Constraint>,
    /// The model's springs.
    pub springs: Vec<Spring>,
    /// The model's dampers.
    pub dampers: Vec<Damper>,
    /// Number of constraint rows.
    pub rows: usize,
    /// The unilateral elements ([`tree_model::Model::gaps`]), their frames as indices into
    /// `frames`.
    pub gaps: Vec<Gap>,
    /// Number of unilateral rows.
    pub gap_rows: usize,
}

/// A frame before ancestor lists and offsets are filled in.
struct Draft {
    parent: Option<usize>,
    pre: Option<Pose>,
    kind: PrimitiveKind,
    joint: Joint,
    needed: bool,
    attached: bool,
    element: bool,
    body: Option<Body>,
}

impl TreePlan {
    /// The plan of every model frame as it is.
    pub fn new(model: &Model) -> Self {
        let (attached, element) = attachments(model);
        let has_mass = lagrangian_reach(model, &element);
        let drafts = model
            .frames
            .iter()
            .enumerate()
            .map(|(k, f)| Draft {
                parent: f.parent,
                pre: None,
                kind: f.primitive,
                joint: f.joint,
                needed: has_mass[k],
                attached: attached[k],
                element: element[k],
                body: f.mass.as_ref().and_then(Body::of),
            })
            .collect();
        Self::from_drafts(model, drafts, (0..model.frames.len()).map(Some).collect())
    }

    /// The plan with constant transforms folded: only driven or attached frames (and massive
    /// ones fixed to the world) remain, each with the constant transform from its nearest
    /// remaining ancestor to its parent in `pre`; a folded frame's body joins that ancestor's
    /// as one composite rigid body.
    pub fn folded(model: &Model) -> Self {
        let (attached, element) = attachments(model);
        let has_mass = lagrangian_reach(model, &element);
        let mut drafts: Vec<Draft> = Vec::new();
        // For each model frame: its index in `drafts` if kept, and the constant transform from
        // the nearest kept ancestor (or the world) to it if not.
        let mut kept: Vec<Option<usize>> = Vec::with_capacity(model.frames.len());
        let mut carried: Vec<Option<Pose>> = Vec::with_capacity(model.frames.len());
        for (k, f) in model.frames.iter().enumerate() {
            let body = f.mass.as_ref().and_then(Body::of);
            // The kept ancestor and the constant transform from it to this frame's parent.
            let (parent, pre) = match f.parent {
                None => (None, None),
                Some(p) => match kept[p] {
                    Some(d) => (Some(d), None),
                    None => (nearest_kept(model, &kept, p), carried[p]),
                },
            };
            // A body on a constant frame fixed to the world (no kept ancestor) keeps its frame,
            // for its constant share of the potential; elsewhere it joins its kept ancestor's.
            let keep = matches!(f.joint, Joint::Variable(_) | Joint::Mimic(_))
                || attached[k]
                || (body.is_some() && parent.is_none());
            if keep {
                let (pre, kind, joint) = match (f.joint, pre) {
                    // A constant frame after a folded chain joins the chain; its own primitive
                    // becomes the identity.
                    (Joint::Constant(x), Some(c)) => (
                        Some(c.compose(&LocalTransform::new(f.primitive, x).pose())),
                        PrimitiveKind::Tx,
                        Joint::Constant(0.0),
                    ),
                    (joint, pre) => (pre, f.primitive, joint),
                };
                kept.push(Some(drafts.len()));
                carried.push(None);
                drafts.push(Draft {
                    parent,
                    pre,
                    kind,
                    joint,
                    needed: has_mass[k],
                    attached: attached[k],
                    element: element[k],
                    body,
                });
            } else {
                let Joint::Constant(x) = f.joint else {
                    unreachable!("driven frames are kept")
                };
                let own = LocalTransform::new(f.primitive, x).pose();
                let g = pre.map_or(own, |c| c.compose(&own));
                // Its body moves rigidly with the kept ancestor: one composite body there.
                if let (Some(b), Some(d)) = (body, parent) {
                    drafts[d].body = Some(Body::joined(drafts[d].body, &b, &g));
                }
                kept.push(None);
                carried.push(Some(g));
            }
        }
        Self::from_drafts(model, drafts, kept)
    }

    fn from_drafts(model: &Model, mut drafts: Vec<Draft>, kept: Vec<Option<usize>>) -> Self {
        let mut frames: Vec<FramePlan> = Vec::with_capacity(drafts.len());
        let mut vars = Vec::new();
        let mut columns = 0;
        let (followers, follower_frames, follower_damping) = followers(model, &mut drafts);
        for d in drafts {
            let var_start = vars.len();
            if let Some(p) = d.parent {
                let (s, n) = (frames[p].var_start, frames[p].n);
                vars.extend_from_within(s..s + n);
            }
            if let Joint::Variable(i) = d.joint {
                vars.push(i);
            }
            let n = vars.len() - var_start;
            frames.push(FramePlan {
                parent: d.parent,
                pre: d.pre.map(ConstantTransform::new),
                kind: d.kind,
                joint: d.joint,
                var_start,
                n,
                col_offset: columns,
                needed: d.needed,
                attached: d.attached,
                leads_to_attached: d.attached,
                leads_to_element: d.element,
                body: d.body,
                subtree_mass: 0.0,
            });
            columns += n;
        }
        for k in (0..frames.len()).rev() {
            frames[k].subtree_mass += frames[k].body.map_or(0.0, |b| b.mass());
            if let Some(p) = frames[k].parent {
                frames[p].subtree_mass += frames[k].subtree_mass;
                frames[p].leads_to_attached |= frames[k].leads_to_attached;
                frames[p].leads_to_element |= frames[k].leads_to_element;
            }
        }
        TreePlan {
            frames,
            pose_frames: model
                .frames
                .iter()
                .map(|f| PoseFrame {
                    parent: f.parent,
                    kind: f.primitive,
                    joint: f.joint,
                })
                .collect(),
            vars,
            variable_frames: model
                .variables
                .iter()
                .map(|v| {
                    v.frame
                        .map(|f| kept[f].expect("driven frames are always kept"))
                })
                .chain(follower_frames.into_iter().map(Some))
                .collect(),
            followers,
            gravity: model.gravity,
            columns,
            damping: (model.variables.iter().map(|v| v.damping))
                .chain(follower_damping)
                .collect(),
            constraints: model
                .constraints
                .iter()
                .map(|c| Constraint {
                    frames: c.frames.map(|f| at(&kept, f)),
                    ..c.clone()
                })
                .collect(),
            springs: model
                .springs
                .iter()
                .map(|s| Spring {
                    kind: match s.kind {
                        SpringKind::Frames(fr) => SpringKind::Frames(fr.map(|f| at(&kept, f))),
                        other => other,
                    },
                    ..*s
                })
                .collect(),
            dampers: model
                .dampers
                .iter()
                .map(|d| Damper {
                    frames: d.frames.map(|f| at(&kept, f)),
                    ..*d
                })
                .collect(),
            rows: model.constraint_rows(),
            gaps: model.gaps().into_iter().map(|g| gap_at(&kept, g)).collect(),
            gap_rows: model.gap_rows(),
        }
    }

    /// The variables that move frame `k`, root first.
    pub fn ancestors(&self, k: usize) -> &[usize] {
        let f = &self.frames[k];
        &self.vars[f.var_start..f.var_start + f.n]
    }

    /// Per constraint row, the model variables it depends on, ascending: those above either
    /// of its frames (a follower's leader for the follower) and a variable length's own. Its
    /// `Dh` row and `D²h` block are zero outside them (docs/derivations.md §5).
    pub fn constraint_variables(&self) -> Vec<Vec<usize>> {
        let mut rows = Vec::with_capacity(self.rows);
        for con in &self.constraints {
            let mut vars: Vec<usize> = con
                .frames
                .iter()
                .flat_map(|&f| self.ancestors(f).iter().map(|&i| self.reduced(i).0))
                .collect();
            if let ConstraintKind::Distance {
                length: Parameter::Variable(i),
            } = con.kind
            {
                vars.push(i);
            }
            vars.sort_unstable();
            vars.dedup();
            rows.extend(std::iter::repeat_n(vars, con.rows()));
        }
        rows
    }

    /// Whether the tree has elements (constraints, springs or dampers).
    pub fn has_elements(&self) -> bool {
        !(self.constraints.is_empty()
            && self.springs.is_empty()
            && self.dampers.is_empty()
            && self.gaps.is_empty())
    }

    /// Number of the model's configuration variables.
    pub fn dof(&self) -> usize {
        self.variable_frames.len() - self.followers.len()
    }

    /// Number of variables in full coordinates: the model's, then the followers.
    pub fn full_dof(&self) -> usize {
        self.variable_frames.len()
    }

    /// Full-coordinate variable `i` as the model's: its variable and `∂q_full,i/∂q` (1 for
    /// the model's own, the multiplier for a follower).
    #[inline(always)]
    pub fn reduced(&self, i: usize) -> (usize, f64) {
        match i.checked_sub(self.dof()) {
            None => (i, 1.0),
            Some(k) => (self.followers[k].leader, self.followers[k].multiplier),
        }
    }

    /// `x` in full coordinates into `out` (`full_dof` long): the model's entries, then each
    /// follower's `multiplier·x_leader`, plus its offset for a configuration (`offsets`),
    /// not for a rate.
    pub fn extend<S: Scalar>(&self, x: &[S], offsets: bool, out: &mut [S]) {
        let n = self.dof();
        out[..n].copy_from_slice(x);
        for (k, f) in self.followers.iter().enumerate() {
            let mut y = x[f.leader];
            if f.multiplier != 1.0 {
                y = y * S::constant(f.multiplier);
            }
            if offsets && f.offset != 0.0 {
                y += S::constant(f.offset);
            }
            out[n + k] = y;
        }
    }
}

/// The mimic frames' variables: each mimic draft's joint becomes its own variable in full
/// coordinates (`model.dof() + k`); its follower, frame (in the plan) and damping.
fn followers(model: &Model, drafts: &mut [Draft]) -> (Vec<Follower>, Vec<usize>, Vec<f64>) {
    let (mut followers, mut frames, mut damping) = (Vec::new(), Vec::new(), Vec::new());
    for (k, d) in drafts.iter_mut().enumerate() {
        if let Joint::Mimic(m) = d.joint {
            d.joint = Joint::Variable(model.dof() + followers.len());
            followers.push(Follower {
                leader: m.variable,
                multiplier: m.multiplier,
                offset: m.offset,
            });
            frames.push(k);
            damping.push(m.damping);
        }
    }
    (followers, frames, damping)
}

/// A gap with its frames as plan indices.
fn gap_at(kept: &[Option<usize>], mut g: Gap) -> Gap {
    match &mut g.kind {
        GapKind::Lower { .. } | GapKind::Upper { .. } => {}
        GapKind::Ground { frame, .. } => *frame = at(kept, *frame),
        GapKind::Spheres { frames, .. } | GapKind::String { frames, .. } => {
            *frames = frames.map(|f| at(kept, f))
        }
    }
    g
}

/// The plan index of model frame `f`, which an element attaches to (so it is kept).
fn at(kept: &[Option<usize>], f: usize) -> usize {
    kept[f].expect("attached frames are always kept")
}

/// For each model frame, whether a constraint, spring or damper attaches to it, and whether
/// a spring or damper does (an element of the Lagrangian's evaluation).
fn attachments(model: &Model) -> (Vec<bool>, Vec<bool>) {
    let mut attached = vec![false; model.frames.len()];
    for k in model.attached_frames() {
        attached[k] = true;
    }
    let mut element = vec![false; model.frames.len()];
    let springs = model.springs.iter().filter_map(|s| match s.kind {
        SpringKind::Frames(f) => Some(f),
        SpringKind::Variable(_) => None,
    });
    for f in springs.chain(model.dampers.iter().map(|d| d.frames)) {
        f.iter().for_each(|&k| element[k] = true);
    }
    (attached, element)
}

/// For each model frame, whether it or a descendant carries a non-zero mass or has a spring
/// or damper attached (`element`): the frames the Lagrangian's sweeps visit.
fn lagrangian_reach(model: &Model, element: &[bool]) -> Vec<bool> {
    let mut reach = element.to_vec();
    for k in (0..model.frames.len()).rev() {
        reach[k] |= model.frames[k].mass.is_some_and(|m| m.is_nonzero());
        if let (true, Some(p)) = (reach[k], model.frames[k].parent) {
            reach[p] = true;
        }
    }
    reach
}

/// The kept frame nearest above model frame `k` (itself not kept).
fn nearest_kept(model: &Model, kept: &[Option<usize>], k: usize) -> Option<usize> {
    let mut at = model.frames[k].parent;
    while let Some(p) = at {
        if let Some(d) = kept[p] {
            return Some(d);
        }
        at = model.frames[p].parent;
    }
    None
}

/// The most Jacobian columns (a frame's `∂v/∂q̇_i` and `∂v/∂q_i` for each variable above it)
/// an interpreted system allocates: about 480 MB, a chain some 3 000 variables deep.
pub const MAX_COLUMNS: usize = 5_000_000;

/// How many Jacobian columns the sweeps keep for `model`: Σ over frames of the variables at
/// or above each (an upper bound for the folded plan), and the most variables at or above
/// any one frame (the tree's depth in variables). O(frames), before anything is built.
pub fn column_count(model: &Model) -> (usize, usize) {
    let mut above = vec![0usize; model.frames.len()];
    let (mut total, mut deepest) = (0usize, 0usize);
    for (k, f) in model.frames.iter().enumerate() {
        let own = usize::from(matches!(f.joint, Joint::Variable(_) | Joint::Mimic(_)));
        above[k] = f.parent.map_or(0, |p| above[p]) + own;
        total = total.saturating_add(above[k]);
        deepest = deepest.max(above[k]);
    }
    (total, deepest)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::articulated::{accelerations, Articulated};
    use crate::kernel::{self, Kernel};
    use crate::order::Order;
    use crate::outputs::{Output, Sink};
    use std::collections::HashMap;

    /// Every output an evaluation hands out, summed by output.
    #[derive(Default)]
    struct Outputs(HashMap<Output, f64>);

    impl Sink<f64> for Outputs {
        fn add(&mut self, at: Output, x: f64) {
            *self.0.entry(at).or_insert(0.0) += x;
        }
    }

    /// Bodies on constant frames behind rotated and shifted chains, with offset centres of
    /// mass and products of inertia: two join one driven frame that has a body of its own,
    /// one joins a driven frame that has none, and one is fixed to the world; below, every
    /// primitive kind drives a body, one of them a kinematic variable.
    pub(crate) const JOINED: &str = r#"
name = "joined"
gravity = [0.4, -0.3, -9.81]

[[frame]]
name = "stand"
tz = 0.5
mass = 3.0
com = [0.1, 0.0, 0.2]
inertia = [0.2, 0.3, 0.1]

[[frame]]
name = "slide"
parent = "stand"
ty = "s"
mass = 2.0
com = [0.1, 0.0, 0.05]
inertia = [0.05, 0.04, 0.06, 0.001, 0.0, 0.002]

[[frame]]
name = "yaw"
parent = "slide"
rz = "a"
mass = 1.2
com = [0.0, 0.05, 0.0]
inertia = [0.02, 0.015, 0.025, 0.001, 0.0, -0.002]

[[frame]]
name = "tilt"
parent = "yaw"
rx = 0.4

[[frame]]
name = "arm"
parent = "tilt"
ty = 0.3
mass = 0.7
com = [0.02, 0.1, -0.01]
inertia = [0.004, 0.003, 0.005, 0.0, 0.0003, 0.0]

[[frame]]
name = "tip"
parent = "arm"
tx = -0.2
mass = 0.2
inertia = [0.001, 0.001, 0.001]

[[frame]]
name = "pitch"
parent = "tip"
ry = "b"

[[frame]]
name = "turn"
parent = "pitch"
rz = 1.1

[[frame]]
name = "link"
parent = "turn"
tz = -0.6
mass = 0.9
com = [0.0, 0.0, -0.1]
inertia = [0.01, 0.012, 0.004, 0.0, 0.001, 0.0]

[[frame]]
name = "reach"
parent = "link"
tx = "r"
mass = 0.5
com = [0.05, 0.0, 0.0]
inertia = [0.002, 0.003, 0.003, 0.0, 0.0004, 0.0]

[[frame]]
name = "wrist"
parent = "reach"
rx = "w"
mass = 0.2
com = [0.0, 0.0, -0.05]
inertia = [0.001, 0.001, 0.0005]

[[frame]]
name = "lift"
parent = "wrist"
tz = "z"
mass = 0.1
inertia = [0.0002, 0.0002, 0.0001]

[variables.s]
[variables.a]
[variables.b]
[variables.r]
kinematic = true
[variables.w]
[variables.z]
"#;

    pub(crate) fn joined() -> Model {
        tree_model::from_toml_str(JOINED, None).expect("the test model is valid")
    }

    #[test]
    fn bodies_on_constant_frames_join_their_kept_ancestors() {
        let plan = TreePlan::folded(&joined());
        // stand (fixed to the world) and the driven frames remain; arm, tip and link joined.
        assert_eq!(plan.frames.len(), 7);
        let mass = |k: usize| plan.frames[k].body.map_or(0.0, |b| b.mass());
        let masses = [0, 1, 2, 3].map(mass);
        assert_eq!(masses, [3.0, 2.0, 1.2 + 0.7 + 0.2, 0.9]);
        assert!(matches!(plan.frames[3].body, Some(Body::Full { .. })));
    }

    /// The joined plan evaluates the same Lagrangian terms and accelerations as the plan
    /// that walks every frame.
    #[test]
    fn joined_bodies_leave_the_lagrangian_and_the_accelerations_as_they_were() {
        let model = joined();
        let (every, folded) = (TreePlan::new(&model), TreePlan::folded(&model));
        let kinematic: Vec<bool> = model.variables.iter().map(|v| v.is_kinematic()).collect();
        let n = kinematic.len();
        for trial in 0..2 {
            let x = |i: usize, s: f64| (1.9 * (i + 4 * trial) as f64 + s).sin() * 1.5;
            let q: Vec<f64> = (0..n).map(|i| x(i, 0.3)).collect();
            let dq: Vec<f64> = (0..n).map(|i| x(i, 1.1)).collect();
            let tau: Vec<f64> = (0..n).map(|i| x(i, 2.3)).collect();
            let [(a, qa), (b, qb)] = [&every, &folded].map(|plan| {
                let mut k = Kernel::new(plan);
                let mut t = Outputs::default();
                kernel::evaluate(plan, &mut k, &q, &dq, Order::Full, &mut t);
                let mut art = Articulated::new(plan);
                // The kinematic variable's prescribed acceleration.
                let mut qdd: Vec<f64> = (0..n).map(|i| x(i, 0.7)).collect();
                crate::sweeps::forward(plan, &mut k.tree, &q, &dq, crate::sweeps::Reach::Motion);
                accelerations(plan, &k.tree, &mut art, &dq, &tau, &kinematic, &mut qdd);
                (t.0, qdd)
            });
            // Every Lagrangian term either plan hands out (an entry one plan leaves out is 0).
            let value = |t: &HashMap<Output, f64>, at: &Output| t.get(at).copied().unwrap_or(0.0);
            let scale = a
                .values()
                .chain(b.values())
                .fold(0.0, |m: f64, x| m.max(x.abs()));
            let mut diff: Vec<(String, f64)> = a
                .keys()
                .chain(b.keys())
                .map(|at| (format!("{at:?}"), (value(&a, at) - value(&b, at)).abs()))
                .collect();
            diff.extend(
                qa.iter()
                    .zip(&qb)
                    .enumerate()
                    .map(|(i, (x, y))| (format!("qdd {i}"), (x - y).abs())),
            );
            assert!(
                a.len() > 3 * n,
                "the full evaluation hands out the Lagrangian's terms"
            );
            for (term, d) in diff {
                assert!(d <= 1e-13 * scale, "{term} differs by {d:e}");
            }
        }
    }
}
