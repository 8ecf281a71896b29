//! One evaluation (all Lagrangian terms, `Order::Full`) and one VI step of the N-link
//! pendulum, interpreted in each evaluation mode. Run: `cargo bench --bench tree`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use tree_mech::integrate::{MidpointVi, ViSettings};
use tree_mech::nalgebra::Dyn;
use tree_mech::runtime::Vector;
use tree_mech::{tree_model, Evaluation, NoForce, Order, System, Terms, TreeSystem};

const SIZES: [usize; 7] = [1, 2, 4, 8, 12, 19, 40];
const MODES: [(&str, Evaluation); 3] = [
    ("sweeps", Evaluation::Sweeps),
    ("cached", Evaluation::Cached),
    ("uncached", Evaluation::Uncached),
];

fn state(n: usize) -> (Vector<Dyn>, Vector<Dyn>) {
    let q = Vector::<Dyn>::from_fn(n, |i, _| 0.3 * ((i as f64) * 0.7).sin());
    let dq = Vector::<Dyn>::from_fn(n, |i, _| 0.5 * ((i as f64) * 1.3).cos());
    (q, dq)
}

fn evaluation(c: &mut Criterion) {
    let mut group = c.benchmark_group("evaluate");
    for n in SIZES {
        let model = tree_model::n_link_pendulum(n);
        for (label, mode) in MODES {
            if mode == Evaluation::Uncached && n > 19 {
                continue;
            }
            let mut sys = TreeSystem::new(&model, mode).unwrap();
            let (q, dq) = state(n);
            let mut terms = Terms::zeros(Dyn(n));
            group.bench_with_input(BenchmarkId::new(label, n), &n, |b, _| {
                b.iter(|| {
                    sys.lagrangian(black_box(&q), black_box(&dq), Order::Full, &mut terms);
                    black_box(terms.l)
                })
            });
        }
    }
    group.finish();
}

fn vi_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("vi_step");
    for n in SIZES {
        let model = tree_model::n_link_pendulum(n);
        for (label, mode) in MODES {
            if mode == Evaluation::Uncached && n > 19 {
                continue;
            }
            let mut sys = TreeSystem::new(&model, mode).unwrap();
            let (q0, dq0) = state(n);
            let mut vi = MidpointVi::new(Dyn(n), ViSettings::default());
            let p0 = vi.initial_momentum(&mut sys, &q0, &dq0);
            let mut next = q0.clone();
            group.bench_with_input(BenchmarkId::new(label, n), &n, |b, _| {
                b.iter_batched_ref(
                    || (q0.clone(), p0.clone()),
                    |(q, p)| {
                        vi.last_velocity.copy_from(&dq0);
                        vi.step(&mut sys, &mut NoForce, 0, 0.0, 0.01, q, p, &mut next)
                            .unwrap();
                    },
                    criterion::BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, evaluation, vi_step);
criterion_main!(benches);
