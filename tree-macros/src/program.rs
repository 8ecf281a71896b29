//! A recorded tape turned into Rust: dead statements dropped, the rest split into functions
//! of bounded size (rustc and LLVM stay linear in the model's size), values that cross a
//! function boundary passed through one scratch array. Each program is compiled twice from
//! one body per function: as recorded, and on x86-64 for AVX2 and FMA — over `f64` with a
//! product read by one sum fused into it ([`fusions`]; the recorded variant computes the same
//! `V::mul_add` as two roundings) — the second called where the CPU has them
//! (`tree_kernel::cpu::fused`).

use proc_macro2::{Ident, TokenStream};
use quote::{format_ident, quote};

use crate::trace::{Node, Term};

/// Statements per generated function.
const CHUNK: usize = 300;

/// Which variants of a program are compiled: both (the recorded one and the one fused for
/// AVX2 and FMA, chosen by the CPU), or the recorded one alone (a large model's, which
/// halves its build).
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Variants {
    Both,
    RecordedOnly,
}

/// A recorded computation and the outputs it must assign: `(target expression, value)`.
pub struct Program {
    pub nodes: Vec<Node>,
    pub outputs: Vec<(TokenStream, Term)>,
}

/// The number type a program is emitted over.
#[derive(Clone, Copy)]
pub enum Flavour<'a> {
    /// `f64` throughout; outputs assigned to their targets (`out.mass[(0, 1)] = …`) in a
    /// storage of type `out_ty`, which keeps the scratch (`out.scratch`, a
    /// `tree_kernel::Scratch`) if `scratch`, else the scratch is a local array.
    F64 {
        out_ty: &'a TokenStream,
        scratch: bool,
    },
    /// Helpers generic over `S: Scalar`, outputs handed to a `Sink<S>`
    /// (`out.add(Output::Mass(0, 1), …)`; the targets are `Output` expressions), called
    /// from a body whose outputs (`tree_kernel::DualOutputs`) instantiate `S` and keep
    /// the scratch.
    Generic,
}

/// A constant as a token: `1.5f64`, `(-1.5f64)`.
pub fn constant(c: f64) -> TokenStream {
    assert!(c.is_finite(), "validated models have finite constants");
    let lit = proc_macro2::Literal::f64_suffixed(c.abs());
    if c.is_sign_negative() {
        quote!((-#lit))
    } else {
        quote!(#lit)
    }
}

/// `name` with everything that is not an ASCII letter or digit turned into `_`, so it can be
/// part of a Rust identifier.
pub(crate) fn identifier_part(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// Each statement's name: `q3_elbow` for variable 3 (`elbow`), `dq3_elbow`, `sin_q3_elbow`,
/// `cos_q3_elbow` for what reads a variable — so a reader of the expansion can map the
/// statements back to the tree's joints — and `t{n}` for the rest.
struct Names(Vec<Ident>);

impl Names {
    fn of(nodes: &[Node], variables: &[&str]) -> Self {
        let clean = |i: usize| format!("{i}_{}", identifier_part(variables[i]).to_lowercase());
        let names = nodes
            .iter()
            .enumerate()
            .map(|(n, node)| {
                let of_q = |t: Term| match t {
                    Term::Var(v) => match nodes[v as usize] {
                        Node::Q(i) => Some(clean(i)),
                        _ => None,
                    },
                    Term::Const(_) => None,
                };
                match *node {
                    Node::Q(i) => format_ident!("q{}", clean(i)),
                    Node::Dq(i) => format_ident!("dq{}", clean(i)),
                    Node::Sin(a) if of_q(a).is_some() => format_ident!("sin_q{}", of_q(a).unwrap()),
                    Node::Cos(a) if of_q(a).is_some() => format_ident!("cos_q{}", of_q(a).unwrap()),
                    _ => format_ident!("t{}", n),
                }
            })
            .collect();
        Names(names)
    }

    fn var(&self, v: u32) -> &Ident {
        &self.0[v as usize]
    }

    fn term(&self, t: Term, generic: bool) -> TokenStream {
        match t {
            Term::Const(c) if generic => {
                let c = constant(c);
                quote!(S::constant(#c))
            }
            Term::Const(c) => constant(c),
            Term::Var(v) => {
                let id = self.var(v);
                quote!(#id)
            }
        }
    }
}

fn operands(node: &Node) -> Vec<Term> {
    match *node {
        Node::Q(_)
        | Node::Dq(_)
        | Node::Tau(_)
        | Node::KinematicQdd(_)
        | Node::Qdd(_)
        | Node::Weight(_) => vec![],
        Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) => vec![a, b],
        Node::Neg(a) | Node::Sin(a) | Node::Cos(a) | Node::Sqrt(a) | Node::Recip(a) => vec![a],
    }
}

fn expression(node: &Node, names: &Names, generic: bool) -> TokenStream {
    let term = |t| names.term(t, generic);
    match *node {
        Node::Q(i) => quote!(q[#i]),
        Node::Dq(i) => quote!(dq[#i]),
        Node::Tau(i) => quote!(out.tau[#i]),
        Node::KinematicQdd(i) => quote!(out.qdd_in[#i]),
        Node::Qdd(i) if generic => quote!(S::constant(out.acceleration(#i))),
        Node::Qdd(i) => quote!(out.acceleration(#i)),
        Node::Weight(r) if generic => quote!(out.weight(#r)),
        Node::Weight(r) => quote!(out.weights[#r]),
        Node::Add(a, b) => {
            let (a, b) = (term(a), term(b));
            quote!(#a + #b)
        }
        Node::Sub(a, b) => {
            let (a, b) = (term(a), term(b));
            quote!(#a - #b)
        }
        Node::Mul(a, b) => {
            let (a, b) = (term(a), term(b));
            quote!(#a * #b)
        }
        Node::Neg(a) => {
            let a = term(a);
            quote!(-#a)
        }
        Node::Sin(a) if generic => {
            let a = term(a);
            quote!(S::sin_cos(#a).0)
        }
        Node::Cos(a) if generic => {
            let a = term(a);
            quote!(S::sin_cos(#a).1)
        }
        Node::Sqrt(a) if generic => {
            let a = term(a);
            quote!(S::sqrt(#a))
        }
        Node::Recip(a) if generic => {
            let a = term(a);
            quote!(S::recip(#a))
        }
        Node::Sin(a) => {
            let a = term(a);
            quote!(#a.sin())
        }
        Node::Cos(a) => {
            let a = term(a);
            quote!(#a.cos())
        }
        Node::Sqrt(a) => {
            let a = term(a);
            quote!(#a.sqrt())
        }
        Node::Recip(a) => {
            let a = term(a);
            quote!(1.0f64 / #a)
        }
    }
}

/// The fused multiply-adds of the `kept` statements: for each sum or difference that reads
/// a product no other statement or output reads (`uses`), computed in the same function
/// (`chunk_of`) and not passed on through the scratch (`slot`), its expression as one
/// `mul_add` — `a·b + c`, `c − a·b = (−a)·b + c`, `a·b − c` rounded once — and the product
/// marked `absorbed` (not emitted). Negation is exact, so each is the recorded operation
/// with one rounding fewer.
fn fusions(
    nodes: &[Node],
    kept: &[usize],
    (uses, chunk_of, slot): (&[usize], &[usize], &[usize]),
    names: &Names,
) -> (Vec<Option<TokenStream>>, Vec<bool>) {
    let n = nodes.len();
    let mut fused: Vec<Option<TokenStream>> = vec![None; n];
    let mut absorbed = vec![false; n];
    let term = |t| names.term(t, false);
    for &i in kept {
        // The product `t` names, if it can be fused into statement i.
        let product = |t: Term, absorbed: &[bool]| match t {
            Term::Var(m) => match nodes[m as usize] {
                Node::Mul(x, y)
                    if uses[m as usize] == 1
                        && chunk_of[m as usize] == chunk_of[i]
                        && slot[m as usize] == usize::MAX
                        && !absorbed[m as usize] =>
                {
                    Some((term(x), term(y), m as usize))
                }
                _ => None,
            },
            Term::Const(_) => None,
        };
        let (expression, m) = match nodes[i] {
            Node::Add(a, b) => match (product(a, &absorbed), product(b, &absorbed)) {
                (Some((x, y, m)), _) => {
                    let c = term(b);
                    (quote!(V::mul_add(#x, #y, #c)), m)
                }
                (None, Some((x, y, m))) => {
                    let c = term(a);
                    (quote!(V::mul_add(#x, #y, #c)), m)
                }
                (None, None) => continue,
            },
            Node::Sub(a, b) => match (product(b, &absorbed), product(a, &absorbed)) {
                (Some((x, y, m)), _) => {
                    let c = term(a);
                    (quote!(V::mul_add(-(#x), #y, #c)), m)
                }
                (None, Some((x, y, m))) => {
                    let c = term(b);
                    (quote!(V::mul_add(#x, #y, -(#c))), m)
                }
                (None, None) => continue,
            },
            _ => continue,
        };
        fused[i] = Some(expression);
        absorbed[m] = true;
    }
    (fused, absorbed)
}

/// The emitted functions of one program.
pub struct Emitted {
    /// Helper functions (associated functions of the generated type).
    pub functions: TokenStream,
    /// The body that calls them in order.
    pub body: TokenStream,
    /// Number of statements kept.
    pub statements: usize,
}

/// Every program of the expansion, traced from the kernel and emitted: over `f64` into the
/// runtime's terms (`first` … `c_full`), the optional ones a model may not have, and those
/// over dual numbers and jets (`duals`).
pub(crate) struct Programs {
    pub(crate) first: Emitted,
    pub(crate) mass: Emitted,
    pub(crate) energy: Emitted,
    pub(crate) dynamics: Emitted,
    pub(crate) full: Emitted,
    pub(crate) poses: Emitted,
    pub(crate) c_first: Emitted,
    pub(crate) c_dynamics: Emitted,
    pub(crate) c_full: Emitted,
    /// `Σ_r w_r D²h_r` over `f64` (constrained models only).
    pub(crate) weighted: Option<Emitted>,
    /// The articulated-body algorithm (models it resolves, without constraints).
    pub(crate) articulated: Option<Emitted>,
    /// The unilateral rows: `φ, Dφ`, and with the impulses' weights `Σ w D²φ` (models with
    /// limits enforced, contacts or slack strings).
    pub(crate) gaps: Option<(Emitted, Emitted)>,
    /// The generic programs, instantiated over dual numbers and jets; `None` for a large
    /// model, whose evaluations over them are the interpreted runtime's (`expand::LEAN_ABOVE`).
    pub(crate) duals: Option<DualPrograms>,
}

/// The programs over dual numbers and jets (what the linearisations and second step
/// derivatives differentiate).
pub(crate) struct DualPrograms {
    pub(crate) d_dynamics: Emitted,
    pub(crate) d_full: Emitted,
    pub(crate) dc_dynamics: Emitted,
    pub(crate) dc_full: Emitted,
    /// `Σ_r w_r D²h_r` over dual numbers (constrained models only).
    pub(crate) weighted: Option<Emitted>,
    /// The inverse dynamics and the constraints over jets.
    pub(crate) inverse: Emitted,
}

impl Programs {
    /// Every program's helper functions (associated functions of the generated type).
    pub(crate) fn functions(&self) -> impl Iterator<Item = &TokenStream> {
        let always = [
            &self.first,
            &self.mass,
            &self.energy,
            &self.dynamics,
            &self.full,
            &self.poses,
            &self.c_first,
            &self.c_dynamics,
            &self.c_full,
        ];
        let duals = self.duals.iter().flat_map(|d| {
            [
                &d.d_dynamics,
                &d.d_full,
                &d.dc_dynamics,
                &d.dc_full,
                &d.inverse,
            ]
            .into_iter()
            .chain(d.weighted.iter())
        });
        let gaps = self.gaps.iter().flat_map(|(a, b)| [a, b]);
        (always.into_iter().chain(self.articulated.iter()))
            .chain(self.weighted.iter())
            .chain(gaps)
            .chain(duals)
            .map(|e| &e.functions)
    }
}

impl Program {
    /// Emits the program as functions named `{prefix}_{n}` taking `(q, dq, s, out)`, over
    /// `flavour`'s number type, and their variant `{prefix}_fma_{n}` for AVX2 and FMA; the
    /// body calls one or the other by the CPU. Each chunk's statements are written once, in
    /// `{prefix}_body_{n}` (over `f64` generic over how its fused multiply-adds round,
    /// `tree_kernel::cpu::MulAdd`), and inlined into both: the compiler checks them once.
    /// `variables` names the model's variables (the statements reading them are named after
    /// them).
    pub fn emit(
        &self,
        prefix: &str,
        variables: &[&str],
        flavour: Flavour,
        variants: Variants,
    ) -> Emitted {
        let generic = matches!(flavour, Flavour::Generic);
        let names = Names::of(&self.nodes, variables);
        let layout = Layout::of(&self.nodes, self.live_statements());
        let outputs = self.outputs_by_chunk(&layout, &names, generic);
        let signature = Signature::new(&flavour, variables.len(), layout.slots);
        let n = self.nodes.len();
        // Over f64 a product one sum alone reads is fused into it; over a generic scalar the
        // statements stay as recorded (the dual numbers' lanes are vectorised instead).
        let (fused, absorbed) = if generic || variants == Variants::RecordedOnly {
            (vec![None; n], vec![false; n])
        } else {
            let uses = self.uses(&layout.kept);
            let at = (&uses[..], &layout.chunk_of[..], &layout.slot[..]);
            fusions(&self.nodes, &layout.kept, at, &names)
        };
        let variant = Variant {
            generic,
            fused: &fused,
            absorbed: &absorbed,
        };
        let mut functions = TokenStream::new();
        let (mut plain_calls, mut fused_calls) = (TokenStream::new(), TokenStream::new());
        let alone = variants == Variants::RecordedOnly;
        let compiled: &[bool] = if alone { &[false] } else { &[false, true] };
        for c in 0..layout.chunks {
            let body = format_ident!("{}_body_{}", prefix, c);
            let stmts = self.chunk_statements(c, &layout, &variant, &names, &signature.ty);
            let chunk_outputs = &outputs[c];
            functions.extend(signature.body(&body, quote!(#stmts #(#chunk_outputs)*)));
            for &fused_variant in compiled {
                let name = if fused_variant {
                    format_ident!("{}_fma_{}", prefix, c)
                } else {
                    format_ident!("{}_{}", prefix, c)
                };
                let function = chunk_function(&name, &body, &layout, fused_variant, &signature);
                functions.extend(if fused_variant || alone {
                    function
                } else {
                    quote!(::tree_mech::__private::__unless_fused_only! { #function })
                });
                let calls = if fused_variant {
                    &mut fused_calls
                } else {
                    &mut plain_calls
                };
                calls.extend(quote!(Self::#name(q, dq, s, out);));
            }
        }
        let body = match variants {
            Variants::Both => dispatch(plain_calls, fused_calls),
            Variants::RecordedOnly => plain_calls,
        };
        Emitted {
            functions,
            body: with_scratch(&flavour, layout.slots, body),
            statements: layout.kept.len(),
        }
    }

    /// How many statements the outputs read (what is emitted, before fusions).
    pub fn kept(&self) -> usize {
        self.live_statements().len()
    }

    /// The statements the outputs read, directly or through others (liveness, backwards
    /// from the outputs), in order.
    fn live_statements(&self) -> Vec<usize> {
        let n = self.nodes.len();
        let mut live = vec![false; n];
        for (_, t) in &self.outputs {
            if let Term::Var(v) = t {
                live[*v as usize] = true;
            }
        }
        for i in (0..n).rev() {
            if live[i] {
                for t in operands(&self.nodes[i]) {
                    if let Term::Var(v) = t {
                        live[v as usize] = true;
                    }
                }
            }
        }
        (0..n).filter(|&i| live[i]).collect()
    }

    /// Each chunk's output statements: assignments over f64, `out.add` over a generic scalar.
    fn outputs_by_chunk(
        &self,
        layout: &Layout,
        names: &Names,
        generic: bool,
    ) -> Vec<Vec<TokenStream>> {
        let mut outputs_by_chunk: Vec<Vec<TokenStream>> = vec![Vec::new(); layout.chunks];
        for (target, t) in &self.outputs {
            let (c, value) = match t {
                Term::Var(v) => (layout.chunk_of[*v as usize], names.term(*t, generic)),
                Term::Const(_) => (0, names.term(*t, generic)),
            };
            outputs_by_chunk[c].push(if generic {
                quote!(out.add(#target, #value);)
            } else {
                quote!(#target = #value;)
            });
        }
        outputs_by_chunk
    }

    /// Each statement's readers among the kept statements and the outputs (for the fusions).
    fn uses(&self, kept: &[usize]) -> Vec<usize> {
        let mut uses = vec![0usize; self.nodes.len()];
        let read = (kept.iter().flat_map(|&i| operands(&self.nodes[i])))
            .chain(self.outputs.iter().map(|(_, t)| *t));
        for t in read {
            if let Term::Var(v) = t {
                uses[v as usize] += 1;
            }
        }
        uses
    }

    /// Chunk `c`'s statements: its imports from the scratch, then its own (fused where the
    /// variant fuses them), each stored to the scratch where a later chunk reads it.
    fn chunk_statements(
        &self,
        c: usize,
        layout: &Layout,
        variant: &Variant,
        names: &Names,
        ty: &TokenStream,
    ) -> TokenStream {
        let mut stmts = TokenStream::new();
        for &v in &layout.imports[c] {
            let (id, s) = (names.var(v), layout.slot[v as usize]);
            stmts.extend(quote!(let #id: #ty = s[#s];));
        }
        let own =
            (layout.kept.iter()).filter(|&&i| layout.chunk_of[i] == c && !variant.absorbed[i]);
        for &i in own {
            let id = names.var(i as u32);
            let e = match &variant.fused[i] {
                Some(e) => e.clone(),
                None => expression(&self.nodes[i], names, variant.generic),
            };
            stmts.extend(quote!(let #id: #ty = #e;));
            if layout.slot[i] != usize::MAX {
                let s = layout.slot[i];
                stmts.extend(quote!(s[#s] = #id;));
            }
        }
        stmts
    }
}

/// Where a program's kept statements go: chunks of [`CHUNK`] statements (one function
/// each), and a scratch slot for every value a later chunk reads.
struct Layout {
    kept: Vec<usize>,
    chunk_of: Vec<usize>,
    chunks: usize,
    slot: Vec<usize>,
    slots: usize,
    /// Each chunk's values from earlier chunks.
    imports: Vec<Vec<u32>>,
}

impl Layout {
    fn of(nodes: &[Node], kept: Vec<usize>) -> Self {
        let n = nodes.len();
        let mut chunk_of = vec![usize::MAX; n];
        for (pos, &i) in kept.iter().enumerate() {
            chunk_of[i] = pos / CHUNK;
        }
        let chunks = kept.len().div_ceil(CHUNK).max(1);
        // Values used in a later chunk than their own get a scratch slot.
        let mut slot = vec![usize::MAX; n];
        let mut slots = 0;
        let mut imports: Vec<Vec<u32>> = vec![Vec::new(); chunks];
        for &i in &kept {
            for t in operands(&nodes[i]) {
                if let Term::Var(v) = t {
                    let (from, to) = (chunk_of[v as usize], chunk_of[i]);
                    if from != to {
                        if slot[v as usize] == usize::MAX {
                            slot[v as usize] = slots;
                            slots += 1;
                        }
                        if !imports[to].contains(&v) {
                            imports[to].push(v);
                        }
                    }
                }
            }
        }
        Layout {
            kept,
            chunk_of,
            chunks,
            slot,
            slots,
            imports,
        }
    }
}

/// How a program's statements are written (`fused[i]`: statement i's fused multiply-add,
/// `V::mul_add(…)`; `absorbed[i]`: folded into another).
struct Variant<'a> {
    /// Over a generic scalar (else `f64`).
    generic: bool,
    fused: &'a [Option<TokenStream>],
    absorbed: &'a [bool],
}

/// The number type and the signature of a program's functions.
struct Signature {
    ty: TokenStream,
    /// `(q, dq, s, out)` with their types.
    parameters: TokenStream,
    generic: bool,
}

impl Signature {
    fn new(flavour: &Flavour, dof: usize, slots: usize) -> Self {
        match flavour {
            Flavour::F64 { out_ty, .. } => Signature {
                ty: quote!(f64),
                parameters: quote!(q: &[f64; #dof], dq: &[f64; #dof], s: &mut [f64; #slots], out: &mut #out_ty),
                generic: false,
            },
            Flavour::Generic => Signature {
                ty: quote!(S),
                parameters: quote!(
                    q: &[S; #dof],
                    dq: &[S; #dof],
                    s: &mut [S; #slots],
                    out: &mut impl ::tree_mech::__private::Sink<S>,
                ),
                generic: true,
            },
        }
    }

    /// The type parameter of a function over a generic scalar.
    fn scalar(&self) -> TokenStream {
        if self.generic {
            quote!(<S: ::tree_mech::__private::Scalar>)
        } else {
            TokenStream::new()
        }
    }

    /// A chunk's statements as one function, inlined into both variants: over `f64`
    /// generic over how its multiply-adds round (`V`), over a generic scalar as recorded.
    fn body(&self, name: &Ident, stmts: TokenStream) -> TokenStream {
        let parameters = &self.parameters;
        let generics = if self.generic {
            self.scalar()
        } else {
            quote!(<V: ::tree_mech::__private::MulAdd>)
        };
        quote! {
            #[doc(hidden)]
            #[inline(always)]
            #[allow(unused_variables, clippy::all)]
            fn #name #generics(#parameters) {
                #stmts
            }
        }
    }
}

/// One chunk's function of one variant, calling the chunk's body: inlined when the program
/// is one chunk; the fused variant compiled for AVX2 and FMA.
fn chunk_function(
    name: &Ident,
    body: &Ident,
    layout: &Layout,
    fused_variant: bool,
    signature: &Signature,
) -> TokenStream {
    let inline = if layout.chunks == 1 {
        quote!(#[inline(always)])
    } else {
        quote!(#[inline(never)])
    };
    // (A function with target features may be inlined, not always.)
    let attributes = match (fused_variant, layout.chunks) {
        (false, _) => quote!(#inline),
        (true, 1) => quote! {
            #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2,fma"))]
            #[inline]
        },
        (true, _) => quote! {
            #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2,fma"))]
            #[inline(never)]
        },
    };
    let call = match (signature.generic, fused_variant) {
        (true, _) => quote!(Self::#body(q, dq, s, out)),
        (false, false) => quote!(Self::#body::<::tree_mech::__private::Plain>(q, dq, s, out)),
        (false, true) => quote!(Self::#body::<::tree_mech::__private::Fused>(q, dq, s, out)),
    };
    let (scalar, parameters) = (signature.scalar(), &signature.parameters);
    quote! {
        #[doc(hidden)]
        #attributes
        #[allow(clippy::all)]
        fn #name #scalar(#parameters) {
            #call
        }
    }
}

/// The calls of one variant or the other by the CPU (where every CPU the build targets runs
/// the fused variant, the recorded one is not compiled: `__unless_fused_only`; `cpu::fused`
/// is then `true`).
fn dispatch(plain_calls: TokenStream, fused_calls: TokenStream) -> TokenStream {
    quote! {
        if ::tree_mech::__private::fused() {
            // SAFETY: on x86-64 the CPU has AVX2 and FMA (`fused` checked); elsewhere
            // the functions have no target features and the block is plain.
            #[allow(unused_unsafe)]
            let () = unsafe { #fused_calls };
        } else {
            ::tree_mech::__private::__unless_fused_only! { let () = { #plain_calls }; }
        }
    }
}

/// `body` with the values passed between functions: the outputs' scratch (allocated once,
/// never cleared: each slot is written before it is read), or a local array.
fn with_scratch(flavour: &Flavour, slots: usize, body: TokenStream) -> TokenStream {
    match flavour {
        Flavour::F64 { scratch: false, .. } => quote! {
            let s = &mut [0.0f64; #slots];
            #body
        },
        _ if slots == 0 => quote! {
            let s = &mut [];
            #body
        },
        _ => quote! {
            let mut scratch = ::core::mem::take(&mut out.scratch);
            let s = scratch.array::<#slots>();
            #body
            out.scratch = scratch;
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A product read once, in its own function, is fused into the sum or difference that
    /// reads it (each form with the right sign); one read twice, or passed to another
    /// function, is not.
    #[test]
    fn products_read_once_are_fused_into_their_sums() {
        use Term::{Const, Var};
        let nodes = [
            Node::Q(0),                    // 0
            Node::Dq(0),                   // 1
            Node::Mul(Var(0), Var(1)),     // 2: read by 3 alone
            Node::Add(Var(1), Var(2)),     // 3: dq + q·dq
            Node::Mul(Var(0), Const(2.0)), // 4: read by 5 alone
            Node::Sub(Var(3), Var(4)),     // 5: t3 − 2q
            Node::Mul(Var(1), Var(1)),     // 6: read by 7 alone
            Node::Sub(Var(6), Var(5)),     // 7: dq² − t5
            Node::Mul(Var(0), Var(0)),     // 8: read by 9 and 10
            Node::Add(Var(8), Var(7)),     // 9
            Node::Add(Var(8), Var(9)),     // 10
            Node::Mul(Var(1), Var(3)),     // 11: in another function
            Node::Add(Var(11), Var(10)),   // 12
        ];
        let names = Names::of(&nodes, &["x"]);
        let kept: Vec<usize> = (0..nodes.len()).collect();
        let mut uses = vec![0; nodes.len()];
        for t in kept.iter().flat_map(|&i| operands(&nodes[i])) {
            if let Var(v) = t {
                uses[v as usize] += 1;
            }
        }
        uses[12] += 1; // the output
        let mut chunk_of = vec![0; nodes.len()];
        chunk_of[12] = 1;
        let slot = vec![usize::MAX; nodes.len()];
        let (fused, absorbed) = fusions(&nodes, &kept, (&uses, &chunk_of, &slot), &names);
        let shown = |i: usize| fused[i].as_ref().map(|e| e.to_string().replace(' ', ""));
        assert_eq!(shown(3).as_deref(), Some("V::mul_add(q0_x,dq0_x,dq0_x)"));
        assert_eq!(shown(5).as_deref(), Some("V::mul_add(-(q0_x),2f64,t3)"));
        assert_eq!(shown(7).as_deref(), Some("V::mul_add(dq0_x,dq0_x,-(t5))"));
        assert_eq!((shown(9), shown(10), shown(12)), (None, None, None));
        let gone: Vec<usize> = (0..nodes.len()).filter(|&i| absorbed[i]).collect();
        assert_eq!(gone, [2, 4, 6]);
    }

    /// What reads a variable is named after it (sanitised, indexed: unique), the rest `t{n}`.
    #[test]
    fn statements_reading_a_variable_are_named_after_it() {
        let nodes = [
            Node::Q(1),
            Node::Sin(Term::Var(0)),
            Node::Cos(Term::Var(0)),
            Node::Dq(0),
            Node::Mul(Term::Var(1), Term::Var(3)),
            Node::Sin(Term::Var(4)),
        ];
        let names = Names::of(&nodes, &["root-x", "Elbow Joint"]);
        let shown: Vec<String> = names.0.iter().map(|i| i.to_string()).collect();
        assert_eq!(
            shown,
            [
                "q1_elbow_joint",
                "sin_q1_elbow_joint",
                "cos_q1_elbow_joint",
                "dq0_root_x",
                "t4",
                "t5"
            ]
        );
    }
}
