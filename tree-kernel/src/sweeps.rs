//! The tree recursions, written once over any [`Scalar`]: evaluated with `f64` by the
//! interpreted system, traced into straight-line Rust by `tree_model!`.
//!
//! One outward sweep gives every frame's pose, body velocity and its columns `∂v/∂q̇_i`,
//! `∂v/∂q_i` (docs/derivations.md §2, paper eqs. (1), (6), (7), (10)). One inward sweep
//! accumulates each subtree at its root: composite inertia `I^c`, momentum wrench `W`, first
//! mass moment `h` (docs/derivations.md §3). Then every derivative entry is O(1). For variable j driving frame f (ξ_j
//! its axis, `γ_f = R_fᵀγ` gravity in f) and any variable i at or above it (column a of f),
//! with `Y = I^c ξ_j` and `Z = I^c ∂v_f/∂q_j`:
//! * `∂L/∂q̇_j = W·ξ_j`, `∂L/∂q_j = W·∂v_f/∂q_j + ξ_j·(m^c γ_f, h × γ_f)`
//! * `M_ij = J_aᵀ Y` (eq. (18))
//! * `∂²L/∂q̇_i∂q_j = Zᵀ J_a + W·[J_a, ξ_j]` (i ≠ j), `∂²L/∂q̇_j∂q_i = (∂v_f/∂q_i)ᵀ Y` (eq. (17))
//! * `∂²L/∂q_i∂q_j = Zᵀ ∂v_f/∂q_i + W·[∂v_f/∂q_i, ξ_j] + ξ_j·(m^c δ, h × δ)`, `δ = γ_f × ω(J_a)`
//!
//! Each is the paper's per-mass sum (eqs. (15)–(18)) with the sum over the subtree taken once,
//! inward, instead of once per mass. Springs, dampers and constraints (`elements`) then add
//! their terms from the world point Jacobians of the frames they attach to (`kernel` runs
//! both).

use tree_model::{Joint, PrimitiveKind};

use crate::order::Order;
use crate::outputs::{Output, Sink};
use crate::plan::{Body, TreePlan};
use crate::scalar::Scalar;
use crate::se3::{
    bracket_with_axis, component, cross, dot, inertia_times, twist_index, zero6, ConstantTransform,
    LocalTransform, Pose, SpatialInertia, Twist, Wrench,
};

/// Per-frame storage for one evaluation (allocated once, reused).
#[derive(Clone, Debug)]
pub struct Workspace<S: Scalar> {
    /// Each frame's primitive at the current q.
    pub local: Vec<LocalTransform<S>>,
    /// Each frame's pose in the world.
    pub pose: Vec<Pose<S>>,
    /// Each frame's body velocity.
    pub velocity: Vec<Twist<S>>,
    /// `∂v_k/∂q̇_a` for each frame's ancestor variables (the body Jacobian columns).
    pub jac: Vec<Twist<S>>,
    /// `∂v_k/∂q_a`.
    pub dv_dq: Vec<Twist<S>>,
    /// Each subtree's composite spatial inertia at its root.
    pub(crate) inertia: Vec<SpatialInertia<S>>,
    /// Each subtree's momentum wrench at its root.
    pub wrench: Vec<Wrench<S>>,
    /// Each subtree's first mass moment at its root.
    pub moment: Vec<[S; 3]>,
    /// World point Jacobian columns `∂p_k/∂q_a = R_k (∂v_k/∂q̇_a)_lin` (attached frames only).
    pub point_jac: Vec<[S; 3]>,
    /// World axes `R_k (∂v_k/∂q̇_a)_ang` of the ancestor variables (attached frames only).
    pub axis: Vec<[S; 3]>,
}

impl<S: Scalar> Workspace<S> {
    /// Buffers sized for `plan`.
    pub fn new(plan: &TreePlan) -> Self {
        let nf = plan.frames.len();
        Workspace {
            local: plan
                .frames
                .iter()
                .map(|f| LocalTransform::new(f.kind, S::zero()))
                .collect(),
            pose: vec![Pose::identity(); nf],
            velocity: vec![zero6(); nf],
            jac: vec![zero6(); plan.columns],
            dv_dq: vec![zero6(); plan.columns],
            inertia: vec![SpatialInertia::default(); nf],
            wrench: vec![zero6(); nf],
            moment: vec![[S::zero(); 3]; nf],
            point_jac: vec![[S::zero(); 3]; plan.columns],
            axis: vec![[S::zero(); 3]; plan.columns],
        }
    }
}

/// A primitive's parameter at `q`: a constant, a variable, or a mimic's `m·q_i + offset`
/// (the model's frames as [`poses`] and [`velocities`] walk them; the plan's own frames are
/// in full coordinates, where a mimic is a variable).
#[inline(always)]
fn joint_value<S: Scalar>(joint: Joint, q: &[S]) -> S {
    match joint {
        Joint::Constant(x) => S::constant(x),
        Joint::Variable(i) => q[i],
        Joint::Mimic(m) => q[m.variable] * S::constant(m.multiplier) + S::constant(m.offset),
    }
}

/// Every frame's pose in the world, `g_sk = g_s,par(k) g_k` (eq. (1)).
pub fn poses<S: Scalar>(plan: &TreePlan, q: &[S], out: &mut [Pose<S>]) {
    for (k, f) in plan.pose_frames.iter().enumerate() {
        let local = LocalTransform::new(f.kind, joint_value(f.joint, q));
        let parent = f.parent.map_or_else(Pose::identity, |p| out[p]);
        out[k] = local.compose_onto(&parent);
    }
}

/// Every model frame's body velocity alone, `v_k = Ad_{g_k⁻¹} v_par + ξ_k q̇_k` (eq. (6)) from
/// the world at rest, over [`TreePlan::pose_frames`] as [`poses`] goes: no columns, O(frames).
pub fn velocities<S: Scalar>(plan: &TreePlan, q: &[S], dq: &[S], out: &mut [Twist<S>]) {
    for (k, f) in plan.pose_frames.iter().enumerate() {
        let local = LocalTransform::new(f.kind, joint_value(f.joint, q));
        let mut v = f.parent.map_or_else(zero6, |p| local.ad_inverse(&out[p]));
        match f.joint {
            Joint::Variable(i) => v[twist_index(f.kind)] += dq[i],
            Joint::Mimic(m) => v[twist_index(f.kind)] += dq[m.variable] * S::constant(m.multiplier),
            Joint::Constant(_) => {}
        }
        out[k] = v;
    }
}

/// What an outward sweep computes, and on which frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// Every frame, with velocities and every column (diagnostics).
    Everything,
    /// What the Lagrangian's terms up to this order need ([`evaluate`], then the springs and
    /// dampers): the frames that carry or lead to mass or an element, with velocities; every
    /// column from [`Order::Dynamics`] on, below it only each frame's own `∂v/∂q` and the
    /// `∂v/∂q̇` columns on the paths to attached frames.
    Lagrangian(Order),
    /// What the constraints need: poses and `∂v/∂q̇` columns on the paths to attached frames
    /// (`h`, `Dh`, `D²h` are built from world points and axes alone).
    Attachments,
    /// What the mass matrix and the potential need ([`mass`]): poses and `∂v/∂q̇` columns on
    /// the frames that carry or lead to mass or an element; no velocities.
    Mass,
    /// What the recursive dynamics (articulated-body, Newton–Euler: gravity enters as the
    /// base's acceleration) and the springs and dampers need: [`Reach::Lagrangian`] at
    /// [`Order::First`] without the world poses, which only the paths to attached frames keep.
    Motion,
    /// What the total energy needs ([`energy`]): [`Reach::Motion`]'s body velocities and
    /// world poses (on the paths to attached frames only), without columns.
    Energy,
}

/// The outward sweep: poses, body velocities and their columns (eqs. (1), (6), (7), (10)),
/// as much of them as `reach` asks for.
pub fn forward<S: Scalar>(plan: &TreePlan, ws: &mut Workspace<S>, q: &[S], dq: &[S], reach: Reach) {
    forward_inline(plan, ws, q, dq, reach);
}

/// [`forward`], inlined into its caller (a caller compiled for wider registers takes the
/// sweep with it).
#[inline(always)]
pub(crate) fn forward_inline<S: Scalar>(
    plan: &TreePlan,
    ws: &mut Workspace<S>,
    q: &[S],
    dq: &[S],
    reach: Reach,
) {
    // Velocities; every `∂v/∂q̇` column; every `∂v/∂q` column.
    let (velocities, all_jac, all_dv_dq) = match reach {
        Reach::Everything => (true, true, true),
        Reach::Lagrangian(order) => (true, order >= Order::Dynamics, order >= Order::Dynamics),
        Reach::Attachments => (false, false, false),
        Reach::Mass => (false, true, false),
        Reach::Motion => (true, false, false),
        Reach::Energy => (true, false, false),
    };
    for (k, f) in plan.frames.iter().enumerate() {
        let visit = match reach {
            Reach::Everything => true,
            Reach::Lagrangian(_) | Reach::Mass | Reach::Motion | Reach::Energy => f.needed,
            Reach::Attachments => f.leads_to_attached,
        };
        if !visit {
            continue;
        }
        // The constraints' reach reads only attached frames' world columns, which
        // `world_columns` forms from the poses on the way: no body columns transported.
        let velocity_columns = all_jac
            || match reach {
                Reach::Lagrangian(_) | Reach::Mass | Reach::Motion => f.leads_to_element,
                Reach::Everything => f.leads_to_attached,
                Reach::Attachments | Reach::Energy => false,
            };
        let local = LocalTransform::new(f.kind, joint_value(f.joint, q));
        let (mut parent_pose, mut parent_vel, np, pc) = match f.parent {
            Some(p) => (
                ws.pose[p],
                ws.velocity[p],
                plan.frames[p].n,
                plan.frames[p].col_offset,
            ),
            None => (Pose::identity(), zero6(), 0, 0),
        };
        // The world pose, unless only the motion is asked for away from attachments.
        let pose = !matches!(reach, Reach::Motion | Reach::Energy) || f.leads_to_attached;
        // A folded constant transform comes first: g = C g_k(x).
        if let Some(c) = &f.pre {
            if pose {
                parent_pose = c.compose_onto(&parent_pose);
            }
            if velocities {
                parent_vel = c.ad_inverse(&parent_vel);
            }
        }
        ws.local[k] = local;
        if pose {
            ws.pose[k] = local.compose_onto(&parent_pose);
        }
        let kc = f.col_offset;
        if velocities {
            // v_k = Ad_{g_k⁻¹} v_par + ξ_k q̇_k (eq. (6)).
            let transported = local.ad_inverse(&parent_vel);
            let mut v = transported;
            if let Joint::Variable(i) = f.joint {
                let axis = twist_index(f.kind);
                v[axis] += dq[i];
            }
            ws.velocity[k] = v;
            // The own column of ∂v/∂q is [Ad v_par, ξ_k] (eq. (10)).
            if let Some(d) = f.own().filter(|_| reach != Reach::Energy) {
                ws.dv_dq[kc + d] = bracket_with_axis(&transported, f.kind);
            }
        }
        // Columns of variables above k transport (eqs. (7), (10)); the own ∂v/∂q̇ is ξ_k.
        if velocity_columns {
            transport(&local, f.pre.as_ref(), &mut ws.jac, pc, kc, np);
            if let Some(d) = f.own() {
                ws.jac[kc + d] = f.kind.twist().map(S::constant);
            }
        }
        if all_dv_dq {
            transport(&local, f.pre.as_ref(), &mut ws.dv_dq, pc, kc, np);
        }
        if f.attached && velocity_columns {
            let pose = ws.pose[k];
            for a in 0..f.n {
                let j = ws.jac[kc + a];
                ws.point_jac[kc + a] = pose.rotate(&[j[0], j[1], j[2]]);
                ws.axis[kc + a] = pose.rotate(&[j[3], j[4], j[5]]);
            }
        } else if f.attached && reach == Reach::Attachments {
            world_columns(plan, ws, k);
        }
    }
}

/// Attached frame `k`'s world point Jacobian columns and axes from the poses of the frames
/// its variables drive (all on its path, so already placed): a rotation about the world axis
/// `w = R_j e` through `p_j` moves k's origin at `w × (p_k − p_j)`, a translation along
/// `R_j e` at that axis — O(depth) for the frame, where transporting body columns down the
/// path costs O(depth) a frame on it.
fn world_columns<S: Scalar>(plan: &TreePlan, ws: &mut Workspace<S>, k: usize) {
    let f = &plan.frames[k];
    let p = ws.pose[k].p;
    for a in 0..f.n {
        let i = plan.vars[f.var_start + a];
        let j = plan.variable_frames[i].expect("a variable above a frame drives a frame");
        let (driver, kind) = (&ws.pose[j], plan.frames[j].kind);
        let e = kind.axis();
        let axis = [driver.r[0][e], driver.r[1][e], driver.r[2][e]];
        let zero = [S::zero(); 3];
        let (point, turn) = if kind.is_rotation() {
            let lever = [p[0] - driver.p[0], p[1] - driver.p[1], p[2] - driver.p[2]];
            (cross(&axis, &lever), axis)
        } else {
            (axis, zero)
        };
        ws.point_jac[f.col_offset + a] = point;
        ws.axis[f.col_offset + a] = turn;
    }
}

/// A parent's `n` columns at `from` transported into its child's at `to` (`to ≥ from + n`):
/// `Ad_{g_k⁻¹} Ad_{C⁻¹} X` for the child's primitive `local` after its folded constant `pre`.
fn transport<S: Scalar>(
    local: &LocalTransform<S>,
    pre: Option<&ConstantTransform>,
    columns: &mut [Twist<S>],
    from: usize,
    to: usize,
    n: usize,
) {
    let (head, tail) = columns.split_at_mut(to);
    let dst = &mut tail[..n];
    match pre {
        None => dst.copy_from_slice(&head[from..from + n]),
        Some(c) => c.ad_inverse_each(&head[from..from + n], dst),
    }
    local.ad_inverse_each(dst);
}

/// The inward sweep: each subtree's momentum wrench and first mass moment (and, from
/// `Order::Dynamics` on, composite inertia) at its root. Returns the Lagrangian `L` (eq. (15)).
/// Without `kinetic` (no velocities computed: the state at rest) the wrenches are zero and `L`
/// is `−V`.
#[inline(always)]
fn inward<S: Scalar>(plan: &TreePlan, ws: &mut Workspace<S>, order: Order, kinetic: bool) -> S {
    let gravity = plan.gravity.map(S::constant);
    let dynamics = order >= Order::Dynamics;
    let mut l = S::zero();
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        ws.moment[k] = [S::zero(); 3];
        match f.body {
            Some(Body::Principal { mass, moments }) => {
                let p = &ws.pose[k].p;
                if kinetic {
                    let v = &ws.velocity[k];
                    ws.wrench[k] = inertia_times(mass, &moments, v);
                    l += S::constant(0.5) * dot(v, &ws.wrench[k]);
                } else {
                    ws.wrench[k] = zero6();
                }
                l +=
                    S::constant(mass) * (gravity[0] * p[0] + gravity[1] * p[1] + gravity[2] * p[2]);
                if dynamics {
                    ws.inertia[k] = SpatialInertia::diagonal(mass, &moments);
                }
            }
            // The centre of mass at p + R c enters the potential and the first mass moment
            // h = m c.
            Some(Body::Full { mass, com, inertia }) => {
                let inertia = inertia.constant::<S>();
                let pose = &ws.pose[k];
                let g_local = pose.rotate_inverse(&gravity);
                let (com, mass) = (com.map(S::constant), S::constant(mass));
                if kinetic {
                    ws.wrench[k] = inertia.times(&ws.velocity[k]);
                    l += S::constant(0.5) * dot(&ws.velocity[k], &ws.wrench[k]);
                } else {
                    ws.wrench[k] = zero6();
                }
                ws.moment[k] = com.map(|x| mass * x);
                l += mass
                    * (gravity[0] * pose.p[0]
                        + gravity[1] * pose.p[1]
                        + gravity[2] * pose.p[2]
                        + g_local[0] * com[0]
                        + g_local[1] * com[1]
                        + g_local[2] * com[2]);
                if dynamics {
                    ws.inertia[k] = inertia;
                }
            }
            None => {
                ws.wrench[k] = zero6();
                if dynamics {
                    ws.inertia[k] = SpatialInertia::default();
                }
            }
        }
    }
    // Children come after their parents: walking backwards, each is complete when added.
    for k in (0..plan.frames.len()).rev() {
        let f = &plan.frames[k];
        let Some(p) = f.parent.filter(|_| f.needed) else {
            continue;
        };
        let local = ws.local[k];
        let mut w = local.wrench_to_parent(&ws.wrench[k]);
        let mut h = local.moment_to_parent(&ws.moment[k], f.subtree_mass);
        if let Some(c) = &f.pre {
            w = c.wrench_to_parent(&w);
            h = c.moment_to_parent(&h, f.subtree_mass);
        }
        for c in 0..3 {
            ws.moment[p][c] += h[c];
        }
        for c in 0..6 {
            ws.wrench[p][c] += w[c];
        }
        if dynamics {
            let mut i = local.inertia_to_parent(&ws.inertia[k]);
            if let Some(c) = &f.pre {
                i = c.inertia_to_parent(&i);
            }
            ws.inertia[p].add(&i);
        }
    }
    l
}

/// `b` with `w·[x, ξ] = x·b` for every twist `x` (`ξ` the unit twist of `kind`, `[x, ξ]` as
/// [`bracket_with_axis`]): `(e × f, e × τ)` for a rotation about `e`, `(0, e × f)` for a
/// translation along it, `w = (f, τ)`.
fn bracket_covector<S: Scalar>(w: &Wrench<S>, kind: PrimitiveKind) -> [S; 6] {
    let (f, tau) = ([w[0], w[1], w[2]], [w[3], w[4], w[5]]);
    let e = kind.twist();
    let axis = [e[3] + e[0], e[4] + e[1], e[5] + e[2]].map(S::constant);
    let ef = cross(&axis, &f);
    if kind.is_rotation() {
        let et = cross(&axis, &tau);
        [ef[0], ef[1], ef[2], et[0], et[1], et[2]]
    } else {
        [S::zero(), S::zero(), S::zero(), ef[0], ef[1], ef[2]]
    }
}

/// `c` with `ξ·(m^c δ, h × δ) = c·ω` for `δ = γ × ω` (the gravity term of `∂²L/∂q_i∂q_j`):
/// `m^c (e × γ)` for a translation along `e`, `(e × h) × γ` for a rotation about it.
fn gravity_covector<S: Scalar>(kind: PrimitiveKind, mc: S, h: &[S; 3], g: &[S; 3]) -> [S; 3] {
    let e = kind.twist();
    let axis = [e[3] + e[0], e[4] + e[1], e[5] + e[2]].map(S::constant);
    if kind.is_rotation() {
        cross(&cross(&axis, h), g)
    } else {
        cross(&axis, g).map(|x| mc * x)
    }
}

fn add6<S: Scalar>(a: &[S; 6], b: &[S; 6]) -> [S; 6] {
    [
        a[0] + b[0],
        a[1] + b[1],
        a[2] + b[2],
        a[3] + b[3],
        a[4] + b[4],
        a[5] + b[5],
    ]
}

/// The tree's own Lagrangian terms up to `order` at `(q, q̇)` by the two sweeps (the
/// elements' follow in [`crate::kernel::evaluate`]). Inlined into its caller, as
/// `forward_inline`.
#[inline(always)]
pub fn evaluate<S: Scalar>(
    plan: &TreePlan,
    ws: &mut Workspace<S>,
    q: &[S],
    dq: &[S],
    order: Order,
    out: &mut impl Sink<S>,
) {
    forward_inline(plan, ws, q, dq, Reach::Lagrangian(order));
    let l = inward(plan, ws, order, true);
    out.set(Output::L, l);
    let gravity = plan.gravity.map(S::constant);
    for (j, fk) in plan.variable_frames.iter().enumerate() {
        let Some(fk) = *fk else { continue };
        let f = &plan.frames[fk];
        // A variable with no mass, spring or damper below it has no terms.
        if !f.needed {
            continue;
        }
        let kind = f.kind;
        let own = f.n - 1;
        let kc = f.col_offset;
        let w = ws.wrench[fk];
        let h = ws.moment[fk];
        let mc = S::constant(f.subtree_mass);
        let g = ws.pose[fk].rotate_inverse(&gravity);
        let hg = cross(&h, &g);
        let gravity_wrench = [mc * g[0], mc * g[1], mc * g[2], hg[0], hg[1], hg[2]];
        let dv_own = ws.dv_dq[kc + own];
        out.set(Output::DlDdq(j), component(&w, kind));
        out.set(
            Output::DlDq(j),
            dot(&w, &dv_own) + component(&gravity_wrench, kind),
        );
        if order < Order::Dynamics {
            continue;
        }
        let ic = &ws.inertia[fk];
        let y = ic.column(kind);
        let z = ic.times(&dv_own);
        // The brackets and the gravity term of eq. (17) are linear in the column: `w·[x, ξ_j]
        // = x·b` and `ξ_j·(m^c δ, h × δ) = c·ω(x)` with `δ = γ_f × ω(x)`, so each entry is a
        // dot product with a covector formed once per variable.
        let zb = add6(&z, &bracket_covector(&w, kind));
        let c = (order >= Order::Full).then(|| gravity_covector(kind, mc, &h, &g));
        for a in 0..=own {
            let i = plan.vars[f.var_start + a];
            let ja = ws.jac[kc + a];
            let dva = ws.dv_dq[kc + a];
            let mij = dot(&ja, &y);
            out.set(Output::Mass(i, j), mij);
            if a < own {
                out.set(Output::Mass(j, i), mij);
                out.set(Output::D2lDdqDq(j, i), dot(&dva, &y));
            }
            // ξ_j·b = 0, so the own column (ja = ξ_j) needs no case of its own.
            out.set(Output::D2lDdqDq(i, j), dot(&ja, &zb));
            if let Some(c) = &c {
                let x = dot(&dva, &zb) + c[0] * ja[3] + c[1] * ja[4] + c[2] * ja[5];
                out.set(Output::D2lDqDq(i, j), x);
                if a < own {
                    out.set(Output::D2lDqDq(j, i), x);
                }
            }
        }
    }
}

/// The tree's total energy `E = T + V` at `(q, q̇)`: each body's `½ vᵀ I v` from the outward
/// sweep's body velocities, and the potential `V = −γ·H` from the whole tree's first mass
/// moment `H = Σ m (p + R c)` about the world origin, carried inward as the Lagrangian's
/// sweep carries `h` (eq. (15)'s terms with the potential's sign turned). No world poses
/// (but on the paths to attached frames, for the springs), no columns (the springs'
/// potentials follow in [`crate::kernel::energy`]).
#[inline(always)]
pub fn energy<S: Scalar>(plan: &TreePlan, ws: &mut Workspace<S>, q: &[S], dq: &[S]) -> S {
    forward_inline(plan, ws, q, dq, Reach::Energy);
    let half = S::constant(0.5);
    let mut kinetic = S::zero();
    for (k, f) in plan.frames.iter().enumerate() {
        if !f.needed {
            continue;
        }
        let v = &ws.velocity[k];
        ws.moment[k] = [S::zero(); 3];
        match f.body {
            Some(Body::Principal { mass, moments }) => {
                kinetic += half * dot(v, &inertia_times(mass, &moments, v));
            }
            Some(Body::Full { mass, com, inertia }) => {
                kinetic += half * dot(v, &inertia.constant::<S>().times(v));
                ws.moment[k] = com.map(|x| S::constant(mass * x));
            }
            None => {}
        }
    }
    // Children come after their parents: walking backwards, each is complete when carried
    // to its parent; a root's lands in the world.
    let mut world = [S::zero(); 3];
    for k in (0..plan.frames.len()).rev() {
        let f = &plan.frames[k];
        if !f.needed {
            continue;
        }
        let mut h = ws.local[k].moment_to_parent(&ws.moment[k], f.subtree_mass);
        if let Some(c) = &f.pre {
            h = c.moment_to_parent(&h, f.subtree_mass);
        }
        let to = f.parent.map_or(&mut world, |p| &mut ws.moment[p]);
        for c in 0..3 {
            to[c] += h[c];
        }
    }
    let gravity = plan.gravity.map(S::constant);
    kinetic - (gravity[0] * world[0] + gravity[1] * world[1] + gravity[2] * world[2])
}

/// The mass matrix `M(q)` (eq. (18)) and `L(q, 0) = −V(q)` of the tree at rest: the outward
/// sweep's poses and `∂v/∂q̇` columns and the inward sweep's composite inertias only — no
/// velocities, no `∂v/∂q` columns (Pinocchio's CRBA; about half of an [`Order::Dynamics`]
/// evaluation). Sets [`Output::L`] and every [`Output::Mass`] entry.
pub fn mass<S: Scalar>(plan: &TreePlan, ws: &mut Workspace<S>, q: &[S], out: &mut impl Sink<S>) {
    forward(plan, ws, q, &[], Reach::Mass);
    let l = inward(plan, ws, Order::Dynamics, false);
    out.set(Output::L, l);
    for (j, fk) in plan.variable_frames.iter().enumerate() {
        let Some(fk) = *fk else { continue };
        let f = &plan.frames[fk];
        if !f.needed {
            continue;
        }
        let own = f.n - 1;
        let y = ws.inertia[fk].column(f.kind);
        for a in 0..=own {
            let i = plan.vars[f.var_start + a];
            let mij = dot(&ws.jac[f.col_offset + a], &y);
            out.set(Output::Mass(i, j), mij);
            if a < own {
                out.set(Output::Mass(j, i), mij);
            }
        }
    }
}
