//! The `impl System` of a compiled model: each method a function here, calling the
//! programs `expand` emitted (their bodies read `q`, `dq` as arrays of the model's size and
//! write `out`).

use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use tree_kernel::TreePlan;
use tree_model::Model;

use crate::program::{DualPrograms, Programs};

/// The `System` impl: what the model is (sizes, names, initial values), then its
/// evaluations.
pub(crate) fn system_impl(
    name: &syn::Ident,
    model: &Model,
    plan: &TreePlan,
    programs: &Programs,
) -> TokenStream {
    let n = model.dof();
    let description = description_methods(model, plan);
    let constraints = constraints_method(n, programs);
    let lagrangian = lagrangian_method(n, plan, programs);
    let mass_and_energy = mass_and_energy_methods(n, programs);
    let articulated = programs
        .articulated
        .as_ref()
        .map(|e| articulated_method(n, &e.body));
    let weighted = (programs.weighted.as_ref()).map(|f64| weighted_method(n, &f64.body));
    let poses = poses_method(n, model.frames.len(), &programs.poses.body);
    let gaps = (programs.gaps.as_ref())
        .map(|(first, weighted)| gaps_methods(n, &first.body, &weighted.body));
    let dual = match &programs.duals {
        Some(duals) => {
            let weighted = (duals.weighted.as_ref()).map(|d| weighted_dual_method(n, &d.body));
            let inverse = inverse_method(n, &duals.inverse.body);
            let dual = dual_methods(n, duals);
            quote!(#weighted #inverse #dual)
        }
        None => interpreted_dual_methods(),
    };
    quote! {
        impl ::tree_mech::__private::System for #name {
            type N = ::tree_mech::__private::Const<#n>;

            fn dim(&self) -> Self::N {
                ::tree_mech::__private::Const::<#n>
            }

            #description
            #constraints
            #lagrangian
            #mass_and_energy
            #articulated
            #weighted
            #gaps
            #poses
            #dual
        }
    }
}

/// The model's description: names, initial values, damping, inputs, motions and which
/// variables each constraint row reads.
fn description_methods(model: &Model, plan: &TreePlan) -> TokenStream {
    let (nf, rows) = (model.frames.len(), plan.rows);
    let constraint_variables = plan.constraint_variables();
    quote! {
        fn variable_name(&self, i: usize) -> &str {
            Self::VARIABLES[i]
        }

        fn frame_count(&self) -> usize {
            #nf
        }

        fn frame_name(&self, k: usize) -> &str {
            Self::FRAMES[k]
        }

        fn initial(&self, i: usize) -> (f64, f64) {
            (Self::Q0[i], Self::DQ0[i])
        }

        fn damping(&self, i: usize) -> f64 {
            Self::DAMPING[i]
        }

        fn is_angle(&self, i: usize) -> bool {
            Self::model_ref().is_angle(i)
        }

        fn input_count(&self) -> usize {
            Self::INPUTS.len()
        }

        fn input_name(&self, k: usize) -> &str {
            Self::INPUTS[k]
        }

        fn input_variable(&self, k: usize) -> usize {
            Self::INPUT_VARIABLES[k]
        }

        /// Read from the model (allocates): call it when setting up, not per step.
        fn motion(&self, i: usize) -> Option<::tree_mech::__private::model::Motion> {
            if Self::KINEMATIC[i] {
                Self::model_ref().variables[i].motion.clone()
            } else {
                None
            }
        }

        fn is_kinematic(&self, i: usize) -> bool {
            Self::KINEMATIC[i]
        }

        fn constraint_count(&self) -> usize {
            #rows
        }

        fn constraint_name(&self, r: usize) -> &str {
            Self::CONSTRAINTS[r]
        }

        fn constraint_variables(&self, r: usize) -> Option<&[usize]> {
            const VARIABLES: [&[usize]; #rows] = [#(&[#(#constraint_variables),*]),*];
            VARIABLES.get(r).copied()
        }
    }
}

/// `q` and `dq` as arrays of the model's size, read from the runtime's vectors.
fn state_arrays(n: usize) -> TokenStream {
    quote! {
        let q: &[f64; #n] = &q.data.0[0];
        let dq: &[f64; #n] = &dq.data.0[0];
    }
}

/// `System::constraints`: the program of the asked order.
fn constraints_method(n: usize, programs: &Programs) -> TokenStream {
    let arrays = state_arrays(n);
    let (first, dynamics, full) = (
        &programs.c_first.body,
        &programs.c_dynamics.body,
        &programs.c_full.body,
    );
    quote! {
        fn constraints(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            dq: &::tree_mech::__private::Vector<Self::N>,
            order: ::tree_mech::__private::Order,
            out: &mut ::tree_mech::__private::ConstraintTerms,
        ) {
            out.clear(order);
            #arrays
            match order {
                ::tree_mech::__private::Order::First => { #first }
                ::tree_mech::__private::Order::Dynamics => { #dynamics }
                ::tree_mech::__private::Order::Full => { #full }
            }
        }
    }
}

/// `System::lagrangian`: the program of the asked order, into terms that clear only what it
/// does not assign; the full order marks where it wrote force derivatives.
fn lagrangian_method(n: usize, plan: &TreePlan, programs: &Programs) -> TokenStream {
    let arrays = state_arrays(n);
    let (first, dynamics, full) = (
        &programs.first.body,
        &programs.dynamics.body,
        &programs.full.body,
    );
    // Where the Full evaluation writes force derivatives (elements::forces): dampers fill
    // both matrices, per-variable damping only ∂F/∂q̇'s diagonal.
    let sparsity = if !plan.dampers.is_empty() {
        Some(quote!(Dense))
    } else if plan.damping.iter().any(|&c| c != 0.0) {
        Some(quote!(Diagonal))
    } else {
        None
    };
    let mark_force_derivatives =
        sparsity.map(|s| quote!(out.force_derivatives = ::tree_mech::__private::Sparsity::#s;));
    quote! {
        fn lagrangian(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            dq: &::tree_mech::__private::Vector<Self::N>,
            order: ::tree_mech::__private::Order,
            out: &mut ::tree_mech::__private::Terms<Self::N>,
        ) {
            // Each order's program assigns the same entries on every call: terms kept
            // for it clear only what it does not (`Terms::begin_assigned`). A static's
            // address is this model's own.
            static MODEL: u8 = 0;
            let key = ::core::ptr::addr_of!(MODEL) as usize;
            out.begin_assigned(key, order);
            #arrays
            match order {
                ::tree_mech::__private::Order::First => { #first }
                ::tree_mech::__private::Order::Dynamics => { #dynamics }
                ::tree_mech::__private::Order::Full => { #full #mark_force_derivatives }
            }
            out.end_assigned(key, order);
        }
    }
}

/// `System::mass_matrix` and `System::energy`: the sweeps at rest, and the velocities and
/// first moments alone.
fn mass_and_energy_methods(n: usize, programs: &Programs) -> TokenStream {
    let (mass, energy) = (&programs.mass.body, &programs.energy.body);
    let arrays = state_arrays(n);
    quote! {
        fn mass_matrix(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            out: &mut ::tree_mech::__private::Terms<Self::N>,
        ) {
            out.clear(::tree_mech::__private::Order::Dynamics);
            let q: &[f64; #n] = &q.data.0[0];
            // The traced sweeps read no velocity.
            let dq = q;
            #mass
        }

        fn energy(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            dq: &::tree_mech::__private::Vector<Self::N>,
            out: &mut ::tree_mech::__private::Terms<Self::N>,
        ) -> f64 {
            #arrays
            out.total_energy = 0.0;
            #energy
            out.total_energy
        }
    }
}

/// `System::articulated_acceleration`: the unrolled articulated-body algorithm, its pivots
/// judged as the interpreted system judges them.
fn articulated_method(n: usize, body: &TokenStream) -> TokenStream {
    let arrays = state_arrays(n);
    quote! {
        fn articulated_acceleration(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            dq: &::tree_mech::__private::Vector<Self::N>,
            tau: &::tree_mech::__private::Vector<Self::N>,
            qdd: &mut ::tree_mech::__private::Vector<Self::N>,
            own: &mut ::tree_mech::__private::Terms<Self::N>,
        ) -> bool {
            let mut io = ::tree_mech::__private::ArticulatedIo::<#n>::default();
            io.tau.copy_from_slice(tau.as_slice());
            io.qdd_in.copy_from_slice(qdd.as_slice());
            {
                let out = &mut io;
                #arrays
                #body
            }
            // The model's own forces, as the interpreted system leaves them.
            own.force.as_mut_slice().copy_from_slice(&io.force);
            own.dl_dq.as_mut_slice().copy_from_slice(&io.dl_dq);
            let held = ::tree_mech::__private::pivots_hold(&Self::KINEMATIC, |i| {
                (io.pivot[i], io.pivot_scale[i])
            });
            if held {
                for i in (0..#n).filter(|&i| !Self::KINEMATIC[i]) {
                    qdd[i] = io.qdd[i];
                }
            }
            held
        }
    }
}

/// `System::unilateral` and `System::gaps`: the model's gaps, and the programs that evaluate
/// them (the weighted one assigns what the rows reach, as the constraints' does).
fn gaps_methods(n: usize, first: &TokenStream, weighted: &TokenStream) -> TokenStream {
    quote! {
        fn unilateral(&self) -> ::std::vec::Vec<::tree_mech::__private::model::Gap> {
            Self::model_ref().gaps()
        }

        fn gaps(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            weights: ::core::option::Option<&[f64]>,
            out: &mut ::tree_mech::__private::ConstraintTerms,
        ) {
            let q: &[f64; #n] = &q.data.0[0];
            // The traced sweeps read no velocity.
            let dq = q;
            match weights {
                ::core::option::Option::None => {
                    out.clear(::tree_mech::__private::Order::First);
                    #first
                }
                ::core::option::Option::Some(weights) => {
                    static MODEL: u8 = 0;
                    out.weigh_assigned(weights, ::core::ptr::addr_of!(MODEL) as usize);
                    #weighted
                }
            }
        }
    }
}

/// `System::weighted_constraint_hessian`.
fn weighted_method(n: usize, f64_body: &TokenStream) -> TokenStream {
    quote! {
        fn weighted_constraint_hessian(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            weights: &[f64],
            out: &mut ::tree_mech::__private::ConstraintTerms,
        ) {
            // The entries the constraints reach are assigned, the rest cleared unless
            // kept from this model's last evaluation (`weigh_assigned`). A static's
            // address is this model's own.
            static MODEL: u8 = 0;
            out.weigh_assigned(weights, ::core::ptr::addr_of!(MODEL) as usize);
            let q: &[f64; #n] = &q.data.0[0];
            // The traced sweeps read no velocity.
            let dq = q;
            #f64_body
        }
    }
}

/// `System::weighted_constraint_hessian_dual`.
fn weighted_dual_method(n: usize, dual_body: &TokenStream) -> TokenStream {
    let wrong = "weighted_constraint_hessian_dual takes one dual number per variable ({})";
    quote! {
        fn weighted_constraint_hessian_dual(
            &mut self,
            q: &[::tree_mech::__private::Dual],
            weights: &[::tree_mech::__private::Dual],
            out: &mut ::tree_mech::__private::DualOutputs,
        ) {
            out.weigh(weights);
            let q: &[::tree_mech::__private::Dual; #n] = match q.try_into() {
                Ok(q) => q,
                _ => panic!(#wrong, #n),
            };
            // The traced sweeps read no velocity.
            let dq = q;
            #dual_body
        }
    }
}

/// `System::inverse_dynamics_jet`: the inverse dynamics over jets, accelerations given.
fn inverse_method(n: usize, body: &TokenStream) -> TokenStream {
    quote! {
        #[inline]
        fn inverse_dynamics_jet(
            &mut self,
            q: &[::tree_mech::__private::Jet<{ ::tree_mech::__private::LANES }>],
            dq: &[::tree_mech::__private::Jet<{ ::tree_mech::__private::LANES }>],
            qdd: &[f64],
            out: &mut ::tree_mech::__private::JetOutputs<{ ::tree_mech::__private::LANES }>,
        ) -> bool {
            out.clear();
            out.accelerations.copy_from_slice(qdd);
            let (q, dq): (
                &[::tree_mech::__private::Jet<{ ::tree_mech::__private::LANES }>; #n],
                &[::tree_mech::__private::Jet<{ ::tree_mech::__private::LANES }>; #n],
            ) = match (q.try_into(), dq.try_into()) {
                (Ok(q), Ok(dq)) => (q, dq),
                _ => panic!("inverse_dynamics_jet takes one jet per variable ({})", #n),
            };
            #body
            true
        }
    }
}

/// `System::poses`: every frame's pose.
fn poses_method(n: usize, nf: usize, body: &TokenStream) -> TokenStream {
    quote! {
        fn poses(
            &mut self,
            q: &::tree_mech::__private::Vector<Self::N>,
            out: &mut [::tree_mech::__private::Pose],
        ) {
            assert_eq!(out.len(), #nf, "poses() needs one slot per frame");
            let q: &[f64; #n] = &q.data.0[0];
            let dq = q;
            #body
        }
    }
}

/// `System::evaluate_dual` and `System::constraints_dual`: the generic programs over dual
/// numbers, by order.
fn dual_methods(n: usize, programs: &DualPrograms) -> TokenStream {
    // A dual evaluation's slices as arrays of the model's size (a panic naming the method
    // otherwise).
    let dual_arrays = |method: &str| {
        let wrong = format!("{method} takes one dual number per variable ({{}})");
        quote! {
            let (q, dq): (&[::tree_mech::__private::Dual; #n], &[::tree_mech::__private::Dual; #n]) =
                match (q.try_into(), dq.try_into()) {
                    (Ok(q), Ok(dq)) => (q, dq),
                    _ => panic!(#wrong, #n),
                };
        }
    };
    let (evaluate_arrays, constraints_arrays) = (
        dual_arrays("evaluate_dual"),
        dual_arrays("constraints_dual"),
    );
    let lagrangian = dual_by_order(
        "clear_lagrangian",
        &programs.d_dynamics.body,
        &programs.d_full.body,
    );
    let constraints = dual_by_order(
        "clear_constraints",
        &programs.dc_dynamics.body,
        &programs.dc_full.body,
    );
    quote! {
        #[inline]
        fn evaluate_dual(
            &mut self,
            q: &[::tree_mech::__private::Dual],
            dq: &[::tree_mech::__private::Dual],
            order: ::tree_mech::__private::Order,
            out: &mut ::tree_mech::__private::DualOutputs,
        ) {
            // The constraints first (that call zeroes their outputs), then the Lagrangian.
            <Self as ::tree_mech::__private::System>::constraints_dual(self, q, dq, order, out);
            #evaluate_arrays
            #lagrangian
        }

        fn constraints_dual(
            &mut self,
            q: &[::tree_mech::__private::Dual],
            dq: &[::tree_mech::__private::Dual],
            order: ::tree_mech::__private::Order,
            out: &mut ::tree_mech::__private::DualOutputs,
        ) {
            #constraints_arrays
            #constraints
        }
    }
}

/// A dual evaluation by its order: `clear` (a `DualOutputs` method) zeroes what that order
/// accumulates, then the body runs (first-order outputs are among the Dynamics
/// evaluation's).
fn dual_by_order(clear: &str, dynamics: &TokenStream, full: &TokenStream) -> TokenStream {
    let clear = format_ident!("{clear}");
    quote! {
        match order {
            ::tree_mech::__private::Order::First | ::tree_mech::__private::Order::Dynamics => {
                out.#clear(::tree_mech::__private::Order::Dynamics);
                #dynamics
            }
            ::tree_mech::__private::Order::Full => {
                out.#clear(::tree_mech::__private::Order::Full);
                #full
            }
        }
    }
}

/// A large model's evaluations over dual numbers and jets: the interpreted runtime's, on a
/// twin of the model built once per thread (the same kernel, generic over the scalar).
fn interpreted_dual_methods() -> TokenStream {
    let private = quote!(::tree_mech::__private);
    quote! {
        fn evaluate_dual(
            &mut self,
            q: &[#private::Dual],
            dq: &[#private::Dual],
            order: #private::Order,
            out: &mut #private::DualOutputs,
        ) {
            Self::__interpreted(|twin| twin.evaluate_dual(q, dq, order, out))
        }

        fn constraints_dual(
            &mut self,
            q: &[#private::Dual],
            dq: &[#private::Dual],
            order: #private::Order,
            out: &mut #private::DualOutputs,
        ) {
            Self::__interpreted(|twin| twin.constraints_dual(q, dq, order, out))
        }

        fn weighted_constraint_hessian_dual(
            &mut self,
            q: &[#private::Dual],
            weights: &[#private::Dual],
            out: &mut #private::DualOutputs,
        ) {
            Self::__interpreted(|twin| twin.weighted_constraint_hessian_dual(q, weights, out))
        }

        fn inverse_dynamics_jet(
            &mut self,
            q: &[#private::Jet<{ #private::LANES }>],
            dq: &[#private::Jet<{ #private::LANES }>],
            qdd: &[f64],
            out: &mut #private::JetOutputs<{ #private::LANES }>,
        ) -> bool {
            Self::__interpreted(|twin| twin.inverse_dynamics_jet(q, dq, qdd, out))
        }
    }
}
