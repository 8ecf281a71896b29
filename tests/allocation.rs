//! Hot paths allocate nothing: evaluations and integrator steps, interpreted and generated,
//! counted by a global allocator that tallies the allocations of the thread measuring (the
//! test harness's own threads allocate when they please).

mod common;

use std::alloc::{GlobalAlloc, Layout, System as SystemAlloc};
use std::cell::Cell;

use tree_mech::integrate::{
    JacobianUpdate, MidpointVi, Rk4, Rk45, StepContext, StepCovector, StepDerivatives, Tolerance,
    ViSettings,
};
use tree_mech::nalgebra::{allocator::Allocator, DMatrix, DVector, DefaultAllocator};
use tree_mech::runtime::ModelMotions;
use tree_mech::{
    tree_model, ConstraintTerms, NoForce, Order, PaperEvaluation, PaperSystem, System, Terms,
    TreeSystem,
};

struct Counting;

thread_local! {
    /// Whether this thread is being measured (a const `Cell`: reading it never allocates).
    static MEASURED: Cell<bool> = const { Cell::new(false) };
    /// The allocations this thread made while measured (tests run in parallel threads).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

/// This thread's measured allocations so far.
fn allocated() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if MEASURED.try_with(Cell::get).unwrap_or(false) {
            let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
        }
        unsafe { SystemAlloc.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { SystemAlloc.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

tree_model!(struct Humanoid from "models/humanoid.toml");
tree_model!(struct StringPendulum from "tests/models/string-pendulum.toml");

/// Allocations made by `f`.
fn allocations(f: impl FnOnce()) -> usize {
    let before = allocated();
    MEASURED.with(|m| m.set(true));
    f();
    MEASURED.with(|m| m.set(false));
    allocated() - before
}

/// `derivatives`: also the VI step's derivatives (the paper's reference system evaluates
/// over dual numbers with a fresh kernel, documented as allocating).
fn check<S: System>(mut sys: S, what: &str, derivatives: bool)
where
    DefaultAllocator: Allocator<S::N> + Allocator<S::N, S::N>,
{
    let (mut q, mut dq) = sys.initial_state();
    let mut terms = Terms::zeros(sys.dim());
    let mut constraints = ConstraintTerms::zeros(sys.constraint_count(), sys.dof());
    let mut motion = ModelMotions::of(&sys);
    let mut rk4 = Rk4::new(&sys);
    let mut rk45 = Rk45::new(&sys, Tolerance::default());
    let mut vi = MidpointVi::new(&sys, ViSettings::default());
    let mut vi_reuse = MidpointVi::new(
        &sys,
        ViSettings {
            jacobian: JacobianUpdate::OncePerStep,
            ..ViSettings::default()
        },
    );
    let mut p = vi.initial_momentum(&mut sys, &q, &dq);
    let mut p2 = vi_reuse.initial_momentum(&mut sys, &q, &dq);
    let (mut q2, mut q3, mut next) = (q.clone(), q.clone(), q.clone());
    let (q0, dq0) = (q.clone(), dq.clone());
    // The first pass sets up (a generated system's scratch lives in its outputs, sized on
    // their first evaluation); the next ones must allocate nothing.
    let mut hot = |sys: &mut S, steps: std::ops::Range<usize>| {
        for order in [Order::First, Order::Dynamics, Order::Full] {
            sys.lagrangian(&q0, &dq0, order, &mut terms);
            sys.constraints(&q0, &dq0, order, &mut constraints);
        }
        for k in steps {
            let t = k as f64 * 0.01;
            let mut no_force = NoForce;
            let mut cx = StepContext::new(sys, &mut no_force, &mut motion, 0.01);
            cx.at(k, t);
            rk4.step(&mut cx, &mut q, &mut dq).unwrap();
            rk45.step(&mut cx, 1.0, &mut q, &mut dq).unwrap();
            cx.dt = 0.01;
            vi.step(&mut cx, &mut q2, &mut p, &mut next)
                .unwrap_or_else(|e| panic!("{what}: {e}"));
            vi_reuse.step(&mut cx, &mut q3, &mut p2, &mut next).unwrap();
            vi.velocity_and_energy(&mut cx, &q2, &p, &mut dq).unwrap();
        }
    };
    hot(&mut sys, 0..1);
    let n = allocations(|| hot(&mut sys, 1..20));
    assert_eq!(n, 0, "{what}: {n} allocations in the hot path");
    if !derivatives {
        return;
    }
    // The step's derivatives and their contraction: nothing after the first call.
    let (q1, p1) = (q2.clone(), p.clone());
    let mut first = StepDerivatives::empty();
    let w = StepCovector {
        q2: DVector::from_element(vi.split.dynamic.len(), 1.0),
        p2: DVector::from_element(vi.split.dynamic.len(), 0.5),
        lambda: DVector::from_element(sys.constraint_count(), 0.2),
    };
    let mut hessian = DMatrix::zeros(0, 0);
    let (mut qa, mut pa, mut na) = (q1.clone(), p1.clone(), q1.clone());
    let mut derivatives = |sys: &mut S, vi: &mut MidpointVi<S::N>| {
        let mut no_force = NoForce;
        let mut cx = StepContext::new(sys, &mut no_force, &mut motion, 0.01);
        qa.copy_from(&q1);
        pa.copy_from(&p1);
        vi.step(&mut cx, &mut qa, &mut pa, &mut na).unwrap();
        let q2 = &qa;
        vi.derivatives_into(&mut cx, &q1, &p1, q2, &mut first)
            .unwrap();
        vi.contracted_second_derivatives(&mut cx, &q1, &p1, q2, &w, &mut hessian)
            .unwrap();
    };
    derivatives(&mut sys, &mut vi);
    let n = allocations(|| {
        for _ in 0..3 {
            derivatives(&mut sys, &mut vi);
        }
    });
    assert_eq!(n, 0, "{what}: {n} allocations in the step's derivatives");
}

#[test]
fn evaluations_and_steps_allocate_nothing() {
    check(Humanoid, "generated humanoid", true);
    check(
        TreeSystem::new(&Humanoid::model()).unwrap(),
        "interpreted",
        true,
    );
    for mode in [PaperEvaluation::Cached, PaperEvaluation::Uncached] {
        check(
            PaperSystem::new(&Humanoid::model(), mode).unwrap(),
            &format!("reference {mode:?}"),
            false,
        );
    }
    check(StringPendulum, "generated string pendulum", true);
    check(
        TreeSystem::new(&StringPendulum::model()).unwrap(),
        "interpreted string pendulum",
        true,
    );
    // The counter does count: a Vec allocates.
    assert!(allocations(|| drop(std::hint::black_box(vec![1u8; 16]))) > 0);
}

/// The optimiser's rollout path: a `DiscreteSystem` VI step (an input and a kinematic
/// control, a string constraint) and a knot without derivatives allocate nothing after the
/// first.
#[test]
fn a_discrete_system_step_allocates_nothing() {
    use tree_mech::control::{Control, DiscreteSystem, Knot, Needs};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/trep-vi.toml");
    let m = tree_mech::model::from_toml_file(path).unwrap();
    let hand = m.variable_index("hand_y").unwrap();
    let controls = vec![Control::Input(0), Control::Kinematic(hand)];
    let sys = TreeSystem::new(&m).unwrap();
    let mut d = DiscreteSystem::vi(sys, ViSettings::default(), 0.01, 0.0, controls).unwrap();
    let (q0, dq0) = d.sys.initial_state();
    let x0 = d.state_of(&q0, &dq0, &[0.0, 0.0]);
    let (mut x, mut x2) = (x0.as_slice().to_vec(), vec![0.0; x0.len()]);
    let mut knot = Knot::empty();
    let mut go = |x: &mut Vec<f64>, k: usize| {
        d.knot(k, x, &mut knot, false, Needs::default()).unwrap();
        let u = [0.3, 0.1 + 0.001 * k as f64];
        d.step(k, x, &u, &mut x2, None).unwrap();
        x.copy_from_slice(&x2);
    };
    go(&mut x, 0);
    let n = allocations(|| {
        for k in 1..20 {
            go(&mut x, k);
        }
    });
    assert_eq!(n, 0, "{n} allocations in 19 discrete steps");
}

/// A step linearizer on the caller's thread allocates nothing once its buffers fit the run:
/// the second linearisation of a constrained run with a moving kinematic hand and an input
/// (its first step's momentum formed again included).
#[test]
fn a_trajectory_linearisation_allocates_nothing_once_sized() {
    use tree_mech::integrate::{InputSchedule, Method, SimOptions};
    use tree_mech::runtime::batch::{trajectory, Rollout, StepLinearizer};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/trep-vi.toml");
    let mut sys = TreeSystem::new(&tree_mech::model::from_toml_file(path).unwrap()).unwrap();
    let start = Rollout {
        q0: sys.initial_state().0.as_slice().to_vec(),
        dq0: vec![0.0; sys.dof()],
        inputs: InputSchedule::constant(vec![0.4]),
    };
    let settings = ViSettings::default();
    let options = SimOptions::new(Method::Vi(settings), 0.01, 0.2);
    let run = trajectory(&mut sys, &start, &options, &mut |_| Ok(())).unwrap();
    let mut linearizer = StepLinearizer::new(&sys, &settings, 1).unwrap();
    let mut out = Vec::new();
    linearizer.linearize_into(&run, &mut out).unwrap();
    let n = allocations(|| linearizer.linearize_into(&run, &mut out).unwrap());
    assert_eq!(
        n,
        0,
        "{n} allocations linearising {} steps again",
        out.len()
    );
}

/// No allocation between successive iterations' reports (`counts`: this thread's running
/// count at each report), over at least three iterations.
#[track_caller]
fn none_between(what: &str, counts: &[usize]) {
    assert!(counts.len() >= 3, "{what}: {} iterations", counts.len());
    let per: Vec<usize> = counts.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        per.iter().all(|&a| a == 0),
        "{what}: allocations per iteration {per:?}"
    );
}

/// An iLQR or DDP iteration (backward pass, line search, the accepted rollout's Jacobians)
/// allocates nothing once the solve is set up, on the VI and (iLQR) on RK4: counted between
/// the reports of successive iterations on the cart-pole with limits.
#[test]
fn optimiser_iterations_allocate_nothing() {
    use tree_mech::control::{solve_with, Control, DiscreteSystem, IlqrSettings, Solver};
    let model = tree_mech::model::from_file(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/models/cart.toml"),
        Default::default(),
    )
    .unwrap();
    for (solver, rk4) in [
        (Solver::Ilqr, false),
        (Solver::Ddp, false),
        (Solver::Ilqr, true),
    ] {
        let sys = TreeSystem::new(&model).unwrap();
        let (dt, knots) = (0.02, 30);
        let mut dynamics = if rk4 {
            DiscreteSystem::rk4(sys, dt, 0.0, vec![Control::Input(0)]).unwrap()
        } else {
            DiscreteSystem::new(sys, ViSettings::default(), dt, 0.0).unwrap()
        };
        let (q0, dq0) = dynamics.sys.initial_state();
        let x0 = dynamics.state_of(&q0, &dq0, &[]);
        let mut cost = common::cart_to_half_metre(dt);
        let options = IlqrSettings {
            solver,
            limits: Some((DVector::from_vec(vec![-2.0]), DVector::from_vec(vec![2.0]))),
            max_iterations: 8,
            cost_tolerance: 0.0,
            ..IlqrSettings::default()
        };
        let u0 = vec![DVector::zeros(1); knots];
        let mut counts = Vec::with_capacity(64);
        allocations(|| {
            solve_with(&mut dynamics, &mut cost, &x0, u0, &options, &mut |_| {
                counts.push(allocated());
            })
            .unwrap();
        });
        let integrator = if rk4 { "RK4" } else { "VI" };
        none_between(&format!("{solver:?} on the {integrator}"), &counts);
    }
}

/// The shipped tasks' iterations (task costs: state with velocities, control about gravity,
/// control rate, frame and orientation terms; kinematic controls) allocate nothing either.
#[test]
fn task_iterations_allocate_nothing() {
    use tree_mech::control::{solve_task, TaskOptions};
    for file in ["tasks/ur5-reach.toml", "tasks/cartpole-swingup.toml"] {
        let (task, model) = tree_mech::model::read_task(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file),
        )
        .unwrap();
        let sys = TreeSystem::new(&model).unwrap();
        let options = TaskOptions {
            max_iterations: Some(5),
            ..TaskOptions::default()
        };
        let mut counts = Vec::with_capacity(64);
        allocations(|| {
            solve_task(sys, &task, &model, &options, &mut |_| {
                counts.push(allocated())
            })
            .unwrap();
        });
        none_between(file, &counts);
    }
}

/// A stepper's steps (the VI and RK4, a constraint and a prescribed variable among them)
/// allocate nothing after the first.
#[test]
fn a_stepper_allocates_nothing_a_step() {
    use tree_mech::integrate::{Method, Stepper};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/models/trep-vi.toml");
    let m = tree_mech::model::from_toml_file(path).unwrap();
    for method in [Method::Vi(ViSettings::default()), Method::Rk4] {
        let sys = TreeSystem::new(&m).unwrap();
        let (q0, dq0) = sys.initial_state();
        let mut s = Stepper::new(sys, method, 0.01, q0.as_slice(), dq0.as_slice()).unwrap();
        s.step(&[0.1]).unwrap();
        let n = allocations(|| {
            for k in 0..20 {
                s.step(&[0.1 * k as f64]).unwrap();
                std::hint::black_box(s.energy());
            }
        });
        assert_eq!(n, 0, "{method:?}: {n} allocations in 20 steps");
    }
}

/// Contact steps allocate nothing after the first: the ball's fall, landing (interior point)
/// and rest (its mode), the box sliding (sliding mode), stopping (interior point) and at rest
/// on its four corners (dependent rows in the mode), with the velocity reported each step.
#[test]
fn contact_steps_allocate_nothing() {
    use tree_mech::integrate::{Method, Stepper};
    for (file, steps) in [("ball.toml", 800), ("box.toml", 400)] {
        let path = format!("{}/tests/models/{file}", env!("CARGO_MANIFEST_DIR"));
        let m = tree_mech::model::from_toml_file(path).unwrap();
        let sys = TreeSystem::new(&m).unwrap();
        let (q0, dq0) = sys.initial_state();
        let vi = Method::Vi(ViSettings::default());
        let mut s = Stepper::new(sys, vi, 1e-3, q0.as_slice(), dq0.as_slice()).unwrap();
        s.step(&[]).unwrap();
        let n = allocations(|| {
            for _ in 1..steps {
                s.step(&[]).unwrap();
                std::hint::black_box(s.energy());
            }
        });
        assert_eq!(n, 0, "{file}: {n} allocations in {steps} steps");
    }
}
