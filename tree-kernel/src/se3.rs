//! SE(3) for the tree: poses as `(R, p)`, twists as `(v, ω)` (Murray–Li–Sastry ordering),
//! and the handful of operations the recursions need, each written out per primitive so a
//! product with `rx` touches two columns, not sixteen entries. Generic over [`Scalar`], so
//! the same code evaluates (`f64`) and is compiled by `tree_model!` (a tracing scalar).
//!
//! Facts used throughout (docs/derivations.md §2): a primitive is `g(x) = exp(ξ̂ x)` with a constant unit
//! twist ξ, so `g(x)⁻¹ = g(−x)` and `∂/∂x Ad_{g(x)⁻¹} X = [Ad_{g(x)⁻¹} X, ξ]`.

use tree_model::PrimitiveKind;

use crate::scalar::Scalar;

/// A twist `(v, ω)`: a body velocity, or a column of its derivatives.
pub type Twist<S = f64> = [S; 6];

/// A wrench `(f, τ)` (force and torque), dual to a twist.
pub(crate) type Wrench<S = f64> = [S; 6];

/// The zero twist.
pub const ZERO: Twist = [0.0; 6];

#[inline(always)]
fn c<S: Scalar>(x: f64) -> S {
    S::constant(x)
}

/// The zero twist or wrench of any scalar.
#[inline(always)]
pub fn zero6<S: Scalar>() -> [S; 6] {
    [S::zero(); 6]
}

/// A rigid transform: rotation `r` (row-major 3×3) and translation `p`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose<S = f64> {
    /// Rotation, row-major.
    pub r: [[S; 3]; 3],
    /// Translation.
    pub p: [S; 3],
}

impl Default for Pose {
    fn default() -> Self {
        Pose::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        p: [0.0; 3],
    };

    /// The homogeneous 4×4 matrix, row-major.
    pub fn matrix(&self) -> [[f64; 4]; 4] {
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            m[i][..3].copy_from_slice(&self.r[i]);
            m[i][3] = self.p[i];
        }
        m[3][3] = 1.0;
        m
    }

    /// `self · other` (paper eq. (1): `g_sk = g_s,par(k) g_k`).
    pub fn compose(&self, other: &Pose) -> Pose {
        let mut out = Pose::IDENTITY;
        for i in 0..3 {
            for j in 0..3 {
                out.r[i][j] = (0..3).map(|k| self.r[i][k] * other.r[k][j]).sum();
            }
            out.p[i] = self.p[i] + (0..3).map(|k| self.r[i][k] * other.p[k]).sum::<f64>();
        }
        out
    }

    /// `self⁻¹ = (Rᵀ, −Rᵀp)`.
    pub fn inverse(&self) -> Pose {
        let mut out = Pose::IDENTITY;
        for i in 0..3 {
            for j in 0..3 {
                out.r[i][j] = self.r[j][i];
            }
        }
        for i in 0..3 {
            out.p[i] = -(0..3).map(|k| out.r[i][k] * self.p[k]).sum::<f64>();
        }
        out
    }
}

impl<S: Scalar> Pose<S> {
    /// The identity of any scalar.
    pub fn identity() -> Self {
        let (o, l) = (S::zero(), c(1.0));
        Pose {
            r: [[l, o, o], [o, l, o], [o, o, l]],
            p: [o; 3],
        }
    }

    /// `R a`: a vector in this frame's axes expressed in the world's.
    #[inline(always)]
    pub fn rotate(&self, a: &[S; 3]) -> [S; 3] {
        let r = &self.r;
        [
            r[0][0] * a[0] + r[0][1] * a[1] + r[0][2] * a[2],
            r[1][0] * a[0] + r[1][1] * a[1] + r[1][2] * a[2],
            r[2][0] * a[0] + r[2][1] * a[1] + r[2][2] * a[2],
        ]
    }

    /// `Rᵀ a`: a spatial vector expressed in this frame.
    #[inline(always)]
    pub fn rotate_inverse(&self, a: &[S; 3]) -> [S; 3] {
        let r = &self.r;
        [
            r[0][0] * a[0] + r[1][0] * a[1] + r[2][0] * a[2],
            r[0][1] * a[0] + r[1][1] * a[1] + r[2][1] * a[2],
            r[0][2] * a[0] + r[1][2] * a[1] + r[2][2] * a[2],
        ]
    }
}

/// A primitive transform evaluated at its parameter: for rotations the cosine and sine,
/// for translations the distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalTransform<S = f64> {
    /// Which primitive.
    pub kind: PrimitiveKind,
    /// cos x (rotations) or x (translations).
    pub a: S,
    /// sin x (rotations); unused for translations.
    pub b: S,
}

/// `ξ̂`, the 4×4 matrix of a primitive's unit twist.
fn twist_hat(kind: PrimitiveKind) -> [[f64; 4]; 4] {
    let mut h = [[0.0; 4]; 4];
    let k = kind.axis();
    if kind.is_rotation() {
        let (u, w) = ((k + 1) % 3, (k + 2) % 3);
        h[w][u] = 1.0;
        h[u][w] = -1.0;
    } else {
        h[k][3] = 1.0;
    }
    h
}

fn mat4_mul(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut r = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            r[i][j] = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

impl LocalTransform {
    /// `g'(x) = g(x) ξ̂` (docs/derivations.md §2), as a 4×4 matrix.
    pub fn derivative(&self) -> [[f64; 4]; 4] {
        mat4_mul(&self.pose().matrix(), &twist_hat(self.kind))
    }

    /// `g''(x) = g(x) ξ̂²`.
    pub fn second_derivative(&self) -> [[f64; 4]; 4] {
        let h = twist_hat(self.kind);
        mat4_mul(&self.pose().matrix(), &mat4_mul(&h, &h))
    }

    /// `g(x)⁻¹ = g(−x)`.
    pub fn inverse(&self) -> Self {
        LocalTransform {
            kind: self.kind,
            a: self.a,
            b: if self.kind.is_rotation() {
                -self.b
            } else {
                0.0
            },
        }
        .with_translation_negated()
    }

    fn with_translation_negated(mut self) -> Self {
        if !self.kind.is_rotation() {
            self.a = -self.a;
        }
        self
    }

    /// As a general pose.
    pub fn pose(&self) -> Pose {
        let mut g = Pose::IDENTITY;
        let (c, s) = (self.a, self.b);
        match self.kind {
            PrimitiveKind::Tx => g.p[0] = self.a,
            PrimitiveKind::Ty => g.p[1] = self.a,
            PrimitiveKind::Tz => g.p[2] = self.a,
            PrimitiveKind::Rx => g.r = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
            PrimitiveKind::Ry => g.r = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
            PrimitiveKind::Rz => g.r = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        }
        g
    }
}

impl<S: Scalar> LocalTransform<S> {
    /// `g(x)` for a primitive of this kind.
    #[inline(always)]
    pub fn new(kind: PrimitiveKind, x: S) -> Self {
        if kind.is_rotation() {
            let (s, c) = x.sin_cos();
            LocalTransform { kind, a: c, b: s }
        } else {
            LocalTransform {
                kind,
                a: x,
                b: S::zero(),
            }
        }
    }

    /// `parent · g(x)`, touching only what the primitive changes.
    #[inline(always)]
    pub fn compose_onto(&self, parent: &Pose<S>) -> Pose<S> {
        let mut out = *parent;
        let (c, s) = (self.a, self.b);
        let r = &parent.r;
        match self.kind {
            PrimitiveKind::Tx | PrimitiveKind::Ty | PrimitiveKind::Tz => {
                let k = self.kind.axis();
                for i in 0..3 {
                    out.p[i] += r[i][k] * self.a;
                }
            }
            PrimitiveKind::Rx => {
                for i in 0..3 {
                    out.r[i][1] = c * r[i][1] + s * r[i][2];
                    out.r[i][2] = -s * r[i][1] + c * r[i][2];
                }
            }
            PrimitiveKind::Ry => {
                for i in 0..3 {
                    out.r[i][0] = c * r[i][0] - s * r[i][2];
                    out.r[i][2] = s * r[i][0] + c * r[i][2];
                }
            }
            PrimitiveKind::Rz => {
                for i in 0..3 {
                    out.r[i][0] = c * r[i][0] + s * r[i][1];
                    out.r[i][1] = -s * r[i][0] + c * r[i][1];
                }
            }
        }
        out
    }

    /// [`Self::ad_inverse`] of every twist of `columns`, in place (a frame's Jacobian
    /// columns, eqs. (7), (10)), the primitive matched once for all of them.
    #[inline(always)]
    pub(crate) fn ad_inverse_each(&self, columns: &mut [Twist<S>]) {
        macro_rules! each {
            ($x:ident => $e:expr) => {
                for out in columns.iter_mut() {
                    let $x = *out;
                    *out = $e;
                }
            };
        }
        let (c, s, d) = (self.a, self.b, self.a);
        match self.kind {
            PrimitiveKind::Tx => {
                each!(x => [x[0], x[1] + d * x[5], x[2] - d * x[4], x[3], x[4], x[5]])
            }
            PrimitiveKind::Ty => {
                each!(x => [x[0] - d * x[5], x[1], x[2] + d * x[3], x[3], x[4], x[5]])
            }
            PrimitiveKind::Tz => {
                each!(x => [x[0] + d * x[4], x[1] - d * x[3], x[2], x[3], x[4], x[5]])
            }
            PrimitiveKind::Rx => each!(x => [
                x[0],
                c * x[1] + s * x[2],
                -s * x[1] + c * x[2],
                x[3],
                c * x[4] + s * x[5],
                -s * x[4] + c * x[5],
            ]),
            PrimitiveKind::Ry => each!(x => [
                c * x[0] - s * x[2],
                x[1],
                s * x[0] + c * x[2],
                c * x[3] - s * x[5],
                x[4],
                s * x[3] + c * x[5],
            ]),
            PrimitiveKind::Rz => each!(x => [
                c * x[0] + s * x[1],
                -s * x[0] + c * x[1],
                x[2],
                c * x[3] + s * x[4],
                -s * x[3] + c * x[4],
                x[5],
            ]),
        }
    }

    /// `Ad_{g(x)⁻¹} X`: a parent-frame twist seen from the child (docs/derivations.md §2,
    /// `v_k = Ad_{g_k⁻¹} v_par + ξ q̇`).
    #[inline(always)]
    pub fn ad_inverse(&self, x: &Twist<S>) -> Twist<S> {
        let mut one = [*x];
        self.ad_inverse_each(&mut one);
        one[0]
    }
}

/// `a × e_axis` for a unit axis vector.
#[inline(always)]
fn cross_axis<S: Scalar>(a: [S; 3], axis: usize) -> [S; 3] {
    match axis {
        0 => [S::zero(), a[2], -a[1]],
        1 => [-a[2], S::zero(), a[0]],
        _ => [a[1], -a[0], S::zero()],
    }
}

/// The Lie bracket `[X, ξ] = (ω_X × v_ξ − ω_ξ × v_X, ω_X × ω_ξ)` with a primitive's unit
/// twist ξ: the derivative of a transported twist with respect to the primitive's parameter.
#[inline(always)]
pub fn bracket_with_axis<S: Scalar>(x: &Twist<S>, kind: PrimitiveKind) -> Twist<S> {
    let axis = kind.axis();
    let w = [x[3], x[4], x[5]];
    if kind.is_rotation() {
        let v = cross_axis([x[0], x[1], x[2]], axis);
        let w = cross_axis(w, axis);
        [v[0], v[1], v[2], w[0], w[1], w[2]]
    } else {
        let v = cross_axis(w, axis);
        [v[0], v[1], v[2], S::zero(), S::zero(), S::zero()]
    }
}

/// `x · y` for twists (or a wrench and a twist).
#[inline(always)]
pub fn dot<S: Scalar>(x: &[S; 6], y: &[S; 6]) -> S {
    x[0] * y[0] + x[1] * y[1] + x[2] * y[2] + x[3] * y[3] + x[4] * y[4] + x[5] * y[5]
}

/// `M_k X` with the body's generalized inertia `M_k = diag(m, m, m, Ixx, Iyy, Izz)`.
#[inline(always)]
pub fn inertia_times<S: Scalar>(m: f64, i: &[f64; 3], x: &Twist<S>) -> Wrench<S> {
    let (m, i) = (c::<S>(m), [c::<S>(i[0]), c(i[1]), c(i[2])]);
    [
        m * x[0],
        m * x[1],
        m * x[2],
        i[0] * x[3],
        i[1] * x[4],
        i[2] * x[5],
    ]
}

impl<S: Scalar> LocalTransform<S> {
    /// `Ad_{g(x)⁻¹}ᵀ w`: a child-frame wrench seen from the parent, `(R f, R τ + p × R f)`.
    /// Dual to [`LocalTransform::ad_inverse`]: `(Ad_{g⁻¹}ᵀ w)·X = w·(Ad_{g⁻¹} X)`.
    #[inline(always)]
    pub(crate) fn wrench_to_parent(&self, w: &Wrench<S>) -> Wrench<S> {
        let (c, s, d) = (self.a, self.b, self.a);
        match self.kind {
            // p × f with p = d e_axis
            PrimitiveKind::Tx => [w[0], w[1], w[2], w[3], w[4] - d * w[2], w[5] + d * w[1]],
            PrimitiveKind::Ty => [w[0], w[1], w[2], w[3] + d * w[2], w[4], w[5] - d * w[0]],
            PrimitiveKind::Tz => [w[0], w[1], w[2], w[3] - d * w[1], w[4] + d * w[0], w[5]],
            PrimitiveKind::Rx => [
                w[0],
                c * w[1] - s * w[2],
                s * w[1] + c * w[2],
                w[3],
                c * w[4] - s * w[5],
                s * w[4] + c * w[5],
            ],
            PrimitiveKind::Ry => [
                c * w[0] + s * w[2],
                w[1],
                -s * w[0] + c * w[2],
                c * w[3] + s * w[5],
                w[4],
                -s * w[3] + c * w[5],
            ],
            PrimitiveKind::Rz => [
                c * w[0] - s * w[1],
                s * w[0] + c * w[1],
                w[2],
                c * w[3] - s * w[4],
                s * w[3] + c * w[4],
                w[5],
            ],
        }
    }

    /// `R h + m p`: the first mass moment `h` (about the child origin) of a body of mass `m`,
    /// taken about the parent origin in parent coordinates.
    #[inline(always)]
    pub(crate) fn moment_to_parent(&self, h: &[S; 3], m: f64) -> [S; 3] {
        if self.kind.is_rotation() {
            return self.point_to_parent(h);
        }
        // Added as `m·a`, not as the point's `a` then `(m − 1)·a`: that difference loses
        // every digit of a light body's moment (m = 1e-12: `a − (1 − m)a`).
        let mut r = *h;
        r[self.kind.axis()] += c::<S>(m) * self.a;
        r
    }

    /// `R a + p`: a point of the child frame in parent coordinates.
    #[inline(always)]
    pub(crate) fn point_to_parent(&self, a: &[S; 3]) -> [S; 3] {
        let (c, s, d) = (self.a, self.b, self.a);
        match self.kind {
            PrimitiveKind::Tx => [a[0] + d, a[1], a[2]],
            PrimitiveKind::Ty => [a[0], a[1] + d, a[2]],
            PrimitiveKind::Tz => [a[0], a[1], a[2] + d],
            PrimitiveKind::Rx => [a[0], c * a[1] - s * a[2], s * a[1] + c * a[2]],
            PrimitiveKind::Ry => [c * a[0] + s * a[2], a[1], -s * a[0] + c * a[2]],
            PrimitiveKind::Rz => [c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]],
        }
    }

    /// `Ad_{g⁻¹}ᵀ I Ad_{g⁻¹}`: a child-frame spatial inertia seen from the parent (the
    /// composite-body step). Each primitive's case has its axes as constants, so the
    /// interpreted system runs straight-line code as the compiled one does.
    #[inline(always)]
    pub(crate) fn inertia_to_parent(&self, i: &SpatialInertia<S>) -> SpatialInertia<S> {
        match self.kind {
            PrimitiveKind::Rx => self.inertia_rotated::<0, 1, 2>(i),
            PrimitiveKind::Ry => self.inertia_rotated::<1, 2, 0>(i),
            PrimitiveKind::Rz => self.inertia_rotated::<2, 0, 1>(i),
            PrimitiveKind::Tx => self.inertia_shifted::<0>(i),
            PrimitiveKind::Ty => self.inertia_shifted::<1>(i),
            PrimitiveKind::Tz => self.inertia_shifted::<2>(i),
        }
    }

    /// [`Self::inertia_to_parent`] for a rotation about axis `K` mixing axes `U` and `W`: each
    /// block becomes `R B Rᵀ` (the symmetric ones from their upper triangles).
    #[inline(always)]
    fn inertia_rotated<const K: usize, const U: usize, const W: usize>(
        &self,
        i: &SpatialInertia<S>,
    ) -> SpatialInertia<S> {
        let (c, s) = (self.a, self.b);
        SpatialInertia {
            vv: rotate_symmetric::<S, K, U, W>(&i.vv, c, s),
            vw: rotate_block::<S, U, W>(&i.vw, c, s),
            ww: rotate_symmetric::<S, K, U, W>(&i.ww, c, s),
        }
    }

    /// [`Self::inertia_to_parent`] for a translation along axis `K`: with
    /// `A = [[I, −p̂], [0, I]]`, `vv' = vv`, `vw' = vw − vv p̂`,
    /// `ww' = ww + p̂ vw − (p̂ vv) p̂ − vwᵀ p̂`, where `−vwᵀ p̂ = (p̂ vw)ᵀ`: symmetric, formed
    /// from its upper triangle.
    #[inline(always)]
    fn inertia_shifted<const K: usize>(&self, i: &SpatialInertia<S>) -> SpatialInertia<S> {
        let d = self.a;
        let vw = sub3(&i.vw, &mul_skew(&i.vv, K, d));
        let pvv = skew_mul(K, d, &i.vv);
        let mut ww = i.ww;
        let a = skew_mul(K, d, &i.vw);
        let b = mul_skew(&pvv, K, d);
        for r in 0..3 {
            for c in r..3 {
                ww[r][c] += a[r][c] + a[c][r] - b[r][c];
                ww[c][r] = ww[r][c];
            }
        }
        SpatialInertia { vv: i.vv, vw, ww }
    }
}

/// `R B Rᵀ` for the rotation by `(c, s)` that mixes axes `U` and `W`.
#[inline(always)]
fn rotate_block<S: Scalar, const U: usize, const W: usize>(
    b: &[[S; 3]; 3],
    c: S,
    s: S,
) -> [[S; 3]; 3] {
    let mut r = *b;
    for col in 0..3 {
        r[U][col] = c * b[U][col] - s * b[W][col];
        r[W][col] = s * b[U][col] + c * b[W][col];
    }
    let t = r;
    for row in 0..3 {
        r[row][U] = c * t[row][U] - s * t[row][W];
        r[row][W] = s * t[row][U] + c * t[row][W];
    }
    r
}

/// `R B Rᵀ` for a symmetric `B` and the rotation by `(c, s)` about axis `K` that mixes axes
/// `U` and `W`: `B_KK` stays, `(B_KU, B_KW)` turns as a vector, and the `U`–`W` block takes
/// `c²`, `s²` and `cs` — the upper triangle, mirrored (14 products where the general block
/// takes 24).
#[inline(always)]
fn rotate_symmetric<S: Scalar, const K: usize, const U: usize, const W: usize>(
    b: &[[S; 3]; 3],
    c: S,
    s: S,
) -> [[S; 3]; 3] {
    let (uu, ww, uw, ku, kw) = (b[U][U], b[W][W], b[U][W], b[K][U], b[K][W]);
    let (cc, ss, cs) = (c * c, s * s, c * s);
    let twice = cs * (uw + uw);
    let mut r = *b;
    r[U][U] = cc * uu - twice + ss * ww;
    r[W][W] = ss * uu + twice + cc * ww;
    r[U][W] = cs * (uu - ww) + (cc - ss) * uw;
    r[W][U] = r[U][W];
    r[K][U] = c * ku - s * kw;
    r[U][K] = r[K][U];
    r[K][W] = s * ku + c * kw;
    r[W][K] = r[K][W];
    r
}

/// `d ê_k M`: the cross-product matrix of `d e_k` times `M`.
#[inline(always)]
fn skew_mul<S: Scalar>(k: usize, d: S, m: &[[S; 3]; 3]) -> [[S; 3]; 3] {
    let z = [S::zero(); 3];
    let neg = |r: [S; 3]| [-d * r[0], -d * r[1], -d * r[2]];
    let pos = |r: [S; 3]| [d * r[0], d * r[1], d * r[2]];
    match k {
        0 => [z, neg(m[2]), pos(m[1])],
        1 => [pos(m[2]), z, neg(m[0])],
        _ => [neg(m[1]), pos(m[0]), z],
    }
}

/// `M d ê_k`.
#[inline(always)]
fn mul_skew<S: Scalar>(m: &[[S; 3]; 3], k: usize, d: S) -> [[S; 3]; 3] {
    let mut r = [[S::zero(); 3]; 3];
    for row in 0..3 {
        let x = m[row];
        r[row] = match k {
            0 => [S::zero(), d * x[2], -d * x[1]],
            1 => [-d * x[2], S::zero(), d * x[0]],
            _ => [d * x[1], -d * x[0], S::zero()],
        };
    }
    r
}

#[inline(always)]
fn sub3<S: Scalar>(a: &[[S; 3]; 3], b: &[[S; 3]; 3]) -> [[S; 3]; 3] {
    let mut r = *a;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] -= b[i][j];
        }
    }
    r
}

#[inline(always)]
fn transpose3<S: Scalar>(a: &[[S; 3]; 3]) -> [[S; 3]; 3] {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// A 6×6 symmetric spatial inertia in `(v, ω)` ordering, stored as blocks
/// `[[vv, vw], [vwᵀ, ww]]`; its product with a twist is a wrench (momentum).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialInertia<S = f64> {
    /// Linear–linear block (m 1 for a body).
    pub vv: [[S; 3]; 3],
    /// Linear–angular block (−m ĉ for a body).
    pub vw: [[S; 3]; 3],
    /// Angular–angular block (I_c − m ĉĉ for a body).
    pub ww: [[S; 3]; 3],
}

impl SpatialInertia<f64> {
    /// The spatial inertia at the frame origin of a body of mass `m` with centre of mass `c`
    /// and inertia `i_c` about it (all in the frame's axes):
    /// `[[m 1, −m ĉ], [m ĉ, I_c − m ĉ ĉ]]` (docs/derivations.md §2).
    pub fn body(m: f64, com: &[f64; 3], i_c: &[[f64; 3]; 3]) -> Self {
        let hat = [
            [0.0, -com[2], com[1]],
            [com[2], 0.0, -com[0]],
            [-com[1], com[0], 0.0],
        ];
        let mut s = SpatialInertia::default();
        for r in 0..3 {
            s.vv[r][r] = m;
            for k in 0..3 {
                s.vw[r][k] = -m * hat[r][k];
                let hh: f64 = (0..3).map(|j| hat[r][j] * hat[j][k]).sum();
                s.ww[r][k] = i_c[r][k] - m * hh;
            }
        }
        s
    }

    /// The same inertia in scalar `S` (constants, for the sweeps and the tracer).
    #[inline(always)]
    pub fn constant<S: Scalar>(&self) -> SpatialInertia<S> {
        // Written out: `array::map` here is left as a call, in the articulated-body step too.
        let mut out = SpatialInertia::default();
        for i in 0..3 {
            for j in 0..3 {
                out.vv[i][j] = S::constant(self.vv[i][j]);
                out.vw[i][j] = S::constant(self.vw[i][j]);
                out.ww[i][j] = S::constant(self.ww[i][j]);
            }
        }
        out
    }
}

impl<S: Scalar> Default for SpatialInertia<S> {
    fn default() -> Self {
        let z = [[S::zero(); 3]; 3];
        SpatialInertia {
            vv: z,
            vw: z,
            ww: z,
        }
    }
}

impl<S: Scalar> SpatialInertia<S> {
    /// The body inertia `diag(m, m, m, Ixx, Iyy, Izz)` of a mass at the frame origin.
    pub fn diagonal(m: f64, inertia: &[f64; 3]) -> Self {
        let mut s = SpatialInertia::default();
        for k in 0..3 {
            s.vv[k][k] = c(m);
            s.ww[k][k] = c(inertia[k]);
        }
        s
    }

    /// `self += other` (the symmetric blocks from their upper triangles).
    #[inline(always)]
    pub fn add(&mut self, other: &SpatialInertia<S>) {
        for i in 0..3 {
            for j in 0..3 {
                self.vw[i][j] += other.vw[i][j];
            }
            for j in i..3 {
                self.vv[i][j] += other.vv[i][j];
                self.vv[j][i] = self.vv[i][j];
                self.ww[i][j] += other.ww[i][j];
                self.ww[j][i] = self.ww[i][j];
            }
        }
    }

    /// `self −= s u uᵀ` (the articulated-body step's rank-one update); the symmetric blocks
    /// from their upper triangles, so they stay exactly symmetric.
    #[inline(always)]
    pub(crate) fn sub_outer(&mut self, u: &Wrench<S>, s: S) {
        for i in 0..3 {
            let (a, b) = (s * u[i], s * u[i + 3]);
            for j in 0..3 {
                self.vw[i][j] -= a * u[j + 3];
            }
            for j in i..3 {
                self.vv[i][j] -= a * u[j];
                self.vv[j][i] = self.vv[i][j];
                self.ww[i][j] -= b * u[j + 3];
                self.ww[j][i] = self.ww[i][j];
            }
        }
    }

    /// `I X`.
    #[inline(always)]
    pub fn times(&self, x: &Twist<S>) -> Wrench<S> {
        let mut out = [S::zero(); 6];
        for i in 0..3 {
            out[i] = self.vv[i][0] * x[0]
                + self.vv[i][1] * x[1]
                + self.vv[i][2] * x[2]
                + self.vw[i][0] * x[3]
                + self.vw[i][1] * x[4]
                + self.vw[i][2] * x[5];
            out[i + 3] = self.vw[0][i] * x[0]
                + self.vw[1][i] * x[1]
                + self.vw[2][i] * x[2]
                + self.ww[i][0] * x[3]
                + self.ww[i][1] * x[4]
                + self.ww[i][2] * x[5];
        }
        out
    }

    /// `I ξ` for a primitive's unit twist: one column.
    #[inline(always)]
    pub fn column(&self, kind: PrimitiveKind) -> Wrench<S> {
        let k = kind.axis();
        if kind.is_rotation() {
            [
                self.vw[0][k],
                self.vw[1][k],
                self.vw[2][k],
                self.ww[0][k],
                self.ww[1][k],
                self.ww[2][k],
            ]
        } else {
            [
                self.vv[0][k],
                self.vv[1][k],
                self.vv[2][k],
                self.vw[k][0],
                self.vw[k][1],
                self.vw[k][2],
            ]
        }
    }
}

/// The entry of a twist or wrench `(v, ω)` along a primitive's unit twist ξ.
#[inline(always)]
pub(crate) fn twist_index(kind: PrimitiveKind) -> usize {
    kind.axis() + if kind.is_rotation() { 3 } else { 0 }
}

/// `x · ξ` for a primitive's unit twist: one component.
#[inline(always)]
pub fn component<S: Scalar>(x: &[S; 6], kind: PrimitiveKind) -> S {
    x[twist_index(kind)]
}

/// `a × b`.
#[inline(always)]
pub fn cross<S: Scalar>(a: &[S; 3], b: &[S; 3]) -> [S; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a M` for a constant 3×3 `a` (row-major).
#[inline(always)]
fn const_mul<S: Scalar>(a: &[[f64; 3]; 3], m: &[[S; 3]; 3]) -> [[S; 3]; 3] {
    let mut r = [[S::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] =
                c::<S>(a[i][0]) * m[0][j] + c::<S>(a[i][1]) * m[1][j] + c::<S>(a[i][2]) * m[2][j];
        }
    }
    r
}

/// The cross-product matrix `p̂`.
fn skew(p: &[f64; 3]) -> [[f64; 3]; 3] {
    [[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]]
}

/// `M a` for a constant 3×3 `a`.
#[inline(always)]
fn mul_const<S: Scalar>(m: &[[S; 3]; 3], a: &[[f64; 3]; 3]) -> [[S; 3]; 3] {
    let mut r = [[S::zero(); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] =
                m[i][0] * c::<S>(a[0][j]) + m[i][1] * c::<S>(a[1][j]) + m[i][2] * c::<S>(a[2][j]);
        }
    }
    r
}

/// `M a` for a constant 3×3 `a` when the product is symmetric (`R B Rᵀ`, `p̂ B p̂` for a
/// symmetric `B`): its upper triangle, mirrored.
#[inline(always)]
fn mul_const_symmetric<S: Scalar>(m: &[[S; 3]; 3], a: &[[f64; 3]; 3]) -> [[S; 3]; 3] {
    let mut r = [[S::zero(); 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            r[i][j] =
                m[i][0] * c::<S>(a[0][j]) + m[i][1] * c::<S>(a[1][j]) + m[i][2] * c::<S>(a[2][j]);
            r[j][i] = r[i][j];
        }
    }
    r
}

/// A constant pose — a chain of constant primitives folded into one when the plan is built —
/// acting on values of any scalar. The same operations as [`LocalTransform`], for a general
/// `(R, p)`; identity parts are skipped, and a tracing scalar folds the zeros and ones of `R`.
impl Pose {
    fn is_rotation_free(&self) -> bool {
        self.r == Pose::IDENTITY.r
    }

    fn is_translation_free(&self) -> bool {
        self.p == [0.0; 3]
    }

    /// `parent · self`.
    #[inline(always)]
    pub fn compose_onto<S: Scalar>(&self, parent: &Pose<S>) -> Pose<S> {
        let mut out = *parent;
        for i in 0..3 {
            for j in 0..3 {
                out.r[i][j] = parent.r[i][0] * c::<S>(self.r[0][j])
                    + parent.r[i][1] * c::<S>(self.r[1][j])
                    + parent.r[i][2] * c::<S>(self.r[2][j]);
            }
            out.p[i] = parent.p[i]
                + (parent.r[i][0] * c::<S>(self.p[0])
                    + parent.r[i][1] * c::<S>(self.p[1])
                    + parent.r[i][2] * c::<S>(self.p[2]));
        }
        out
    }

    /// [`Self::ad_inverse`] of every twist of `src` into `dst`, this pose's form (a pure
    /// rotation, a pure translation) found once for all of them.
    pub(crate) fn ad_inverse_each<S: Scalar>(&self, src: &[Twist<S>], dst: &mut [Twist<S>]) {
        let (rotation_free, translation_free) =
            (self.is_rotation_free(), self.is_translation_free());
        let p = self.p.map(c::<S>);
        let r = self.r.map(|row| row.map(c::<S>));
        let rt = |a: [S; 3]| {
            [
                r[0][0] * a[0] + r[1][0] * a[1] + r[2][0] * a[2],
                r[0][1] * a[0] + r[1][1] * a[1] + r[2][1] * a[2],
                r[0][2] * a[0] + r[1][2] * a[1] + r[2][2] * a[2],
            ]
        };
        for (out, x) in dst.iter_mut().zip(src) {
            let w = [x[3], x[4], x[5]];
            let mut v = [x[0], x[1], x[2]];
            if !translation_free {
                let wp = cross(&w, &p);
                v = [v[0] + wp[0], v[1] + wp[1], v[2] + wp[2]];
            }
            *out = if rotation_free {
                [v[0], v[1], v[2], w[0], w[1], w[2]]
            } else {
                let (v, w) = (rt(v), rt(w));
                [v[0], v[1], v[2], w[0], w[1], w[2]]
            };
        }
    }

    /// `Ad_{g⁻¹} X = (Rᵀ(v + ω × p), Rᵀω)`.
    #[inline(always)]
    pub fn ad_inverse<S: Scalar>(&self, x: &Twist<S>) -> Twist<S> {
        let w = [x[3], x[4], x[5]];
        let mut v = [x[0], x[1], x[2]];
        if !self.is_translation_free() {
            let wp = cross(&w, &self.p.map(c::<S>));
            v = [v[0] + wp[0], v[1] + wp[1], v[2] + wp[2]];
        }
        if self.is_rotation_free() {
            return [v[0], v[1], v[2], w[0], w[1], w[2]];
        }
        let rt = |a: &[S; 3]| {
            let r = &self.r;
            [
                c::<S>(r[0][0]) * a[0] + c::<S>(r[1][0]) * a[1] + c::<S>(r[2][0]) * a[2],
                c::<S>(r[0][1]) * a[0] + c::<S>(r[1][1]) * a[1] + c::<S>(r[2][1]) * a[2],
                c::<S>(r[0][2]) * a[0] + c::<S>(r[1][2]) * a[1] + c::<S>(r[2][2]) * a[2],
            ]
        };
        let (v, w) = (rt(&v), rt(&w));
        [v[0], v[1], v[2], w[0], w[1], w[2]]
    }

    /// `R a` for a constant `R`.
    #[inline(always)]
    fn rotate_const<S: Scalar>(&self, a: &[S; 3]) -> [S; 3] {
        if self.is_rotation_free() {
            return *a;
        }
        let r = &self.r;
        [
            c::<S>(r[0][0]) * a[0] + c::<S>(r[0][1]) * a[1] + c::<S>(r[0][2]) * a[2],
            c::<S>(r[1][0]) * a[0] + c::<S>(r[1][1]) * a[1] + c::<S>(r[1][2]) * a[2],
            c::<S>(r[2][0]) * a[0] + c::<S>(r[2][1]) * a[1] + c::<S>(r[2][2]) * a[2],
        ]
    }

    /// `Ad_{g⁻¹}ᵀ w = (R f, R τ + p × R f)`.
    #[inline(always)]
    pub(crate) fn wrench_to_parent<S: Scalar>(&self, w: &Wrench<S>) -> Wrench<S> {
        let f = self.rotate_const(&[w[0], w[1], w[2]]);
        let mut t = self.rotate_const(&[w[3], w[4], w[5]]);
        if !self.is_translation_free() {
            let pf = cross(&self.p.map(c::<S>), &f);
            t = [t[0] + pf[0], t[1] + pf[1], t[2] + pf[2]];
        }
        [f[0], f[1], f[2], t[0], t[1], t[2]]
    }

    /// `R h + m p`: a first mass moment about the child origin, taken about the parent's.
    #[inline(always)]
    pub(crate) fn moment_to_parent<S: Scalar>(&self, h: &[S; 3], m: f64) -> [S; 3] {
        let r = self.rotate_const(h);
        if self.is_translation_free() {
            return r;
        }
        [
            r[0] + c::<S>(m * self.p[0]),
            r[1] + c::<S>(m * self.p[1]),
            r[2] + c::<S>(m * self.p[2]),
        ]
    }

    /// `Ad_{g⁻¹}ᵀ I Ad_{g⁻¹}`: rotate the blocks (`R B Rᵀ`), then shift by `p` as
    /// [`LocalTransform::inertia_to_parent`] does for one axis.
    #[inline(always)]
    pub(crate) fn inertia_to_parent<S: Scalar>(&self, i: &SpatialInertia<S>) -> SpatialInertia<S> {
        let mut out = *i;
        if !self.is_rotation_free() {
            let rt = transpose3(&self.r);
            let rot = |b: &[[S; 3]; 3]| const_mul(&self.r, b);
            out = SpatialInertia {
                vv: mul_const_symmetric(&rot(&i.vv), &rt),
                vw: mul_const(&rot(&i.vw), &rt),
                ww: mul_const_symmetric(&rot(&i.ww), &rt),
            };
        }
        if self.is_translation_free() {
            return out;
        }
        // As the one-axis shift: `−vwᵀ p̂ = (p̂ vw)ᵀ`, and `p̂ vv p̂` is symmetric.
        let p = skew(&self.p);
        let vw = sub3(&out.vw, &mul_const(&out.vv, &p));
        let a = const_mul(&p, &out.vw);
        let b = mul_const_symmetric(&const_mul(&p, &out.vv), &p);
        let mut ww = out.ww;
        for r in 0..3 {
            for s in r..3 {
                ww[r][s] += a[r][s] + a[s][r] - b[r][s];
                ww[s][r] = ww[r][s];
            }
        }
        SpatialInertia { vv: out.vv, vw, ww }
    }
}

/// A constant transform `C` applied before a frame's own primitive (a folded chain of
/// constant primitives, docs/derivations.md §4), its form found once when the plan is built:
/// a single primitive — a translation along an axis, a rotation about one, as most folded
/// offsets are — acts by that primitive's few multiplications; any other pose by the general
/// rotation and shift.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ConstantTransform {
    pose: Pose,
    primitive: Option<LocalTransform>,
}

impl ConstantTransform {
    /// `pose`, classified: a primitive when one reproduces it exactly.
    pub fn new(pose: Pose) -> Self {
        let candidate = |kind: PrimitiveKind| {
            let k = kind.axis();
            let (a, b) = if kind.is_rotation() {
                let (u, w) = ((k + 1) % 3, (k + 2) % 3);
                (pose.r[u][u], pose.r[w][u])
            } else {
                (pose.p[k], 0.0)
            };
            LocalTransform { kind, a, b }
        };
        let primitive = PrimitiveKind::ALL
            .into_iter()
            .map(candidate)
            .find(|t| t.pose() == pose);
        ConstantTransform { pose, primitive }
    }

    /// The primitive in scalar `S` (constants, folded by a tracing scalar).
    #[inline(always)]
    fn lifted<S: Scalar>(t: &LocalTransform) -> LocalTransform<S> {
        LocalTransform {
            kind: t.kind,
            a: c::<S>(t.a),
            b: c::<S>(t.b),
        }
    }

    /// `parent · C`.
    #[inline(always)]
    pub fn compose_onto<S: Scalar>(&self, parent: &Pose<S>) -> Pose<S> {
        match &self.primitive {
            Some(t) => Self::lifted::<S>(t).compose_onto(parent),
            None => self.pose.compose_onto(parent),
        }
    }

    /// `Ad_{C⁻¹} X`: a parent-frame twist seen after `C`.
    #[inline(always)]
    pub fn ad_inverse<S: Scalar>(&self, x: &Twist<S>) -> Twist<S> {
        match &self.primitive {
            Some(t) => Self::lifted::<S>(t).ad_inverse(x),
            None => self.pose.ad_inverse(x),
        }
    }

    /// [`Self::ad_inverse`] of every twist of `src` into `dst`.
    pub(crate) fn ad_inverse_each<S: Scalar>(&self, src: &[Twist<S>], dst: &mut [Twist<S>]) {
        match &self.primitive {
            Some(t) => {
                dst.copy_from_slice(src);
                Self::lifted::<S>(t).ad_inverse_each(dst);
            }
            None => self.pose.ad_inverse_each(src, dst),
        }
    }

    /// `Ad_{C⁻¹}ᵀ w`: a wrench after `C` seen before it.
    #[inline(always)]
    pub(crate) fn wrench_to_parent<S: Scalar>(&self, w: &Wrench<S>) -> Wrench<S> {
        match &self.primitive {
            Some(t) => Self::lifted::<S>(t).wrench_to_parent(w),
            None => self.pose.wrench_to_parent(w),
        }
    }

    /// `R h + m p`: a first mass moment of a subtree of mass `m` taken before `C`.
    #[inline(always)]
    pub(crate) fn moment_to_parent<S: Scalar>(&self, h: &[S; 3], m: f64) -> [S; 3] {
        match &self.primitive {
            Some(t) => Self::lifted::<S>(t).moment_to_parent(h, m),
            None => self.pose.moment_to_parent(h, m),
        }
    }

    /// `Ad_{C⁻¹}ᵀ I Ad_{C⁻¹}`: a spatial inertia after `C` seen before it.
    #[inline(always)]
    pub(crate) fn inertia_to_parent<S: Scalar>(&self, i: &SpatialInertia<S>) -> SpatialInertia<S> {
        match &self.primitive {
            Some(t) => Self::lifted::<S>(t).inertia_to_parent(i),
            None => self.pose.inertia_to_parent(i),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= 1e-15 * (1.0 + x.abs()))
    }

    fn flat(i: &SpatialInertia) -> Vec<f64> {
        [i.vv, i.vw, i.ww]
            .iter()
            .flatten()
            .flatten()
            .copied()
            .collect()
    }

    /// Each single primitive is found and acts as the general pose does; a composite pose
    /// keeps the general form.
    #[test]
    fn a_constant_transform_acts_as_its_pose_whatever_its_form() {
        let twist = [0.3, -1.2, 0.8, 0.5, 0.9, -0.4];
        let wrench = [1.1, 0.2, -0.7, 0.3, -0.6, 0.25];
        let inertia = SpatialInertia::body(
            1.7,
            &[0.1, -0.2, 0.05],
            &[[0.3, 0.01, -0.02], [0.01, 0.2, 0.03], [-0.02, 0.03, 0.25]],
        );
        let parent = LocalTransform::new(PrimitiveKind::Ry, 0.6)
            .pose()
            .compose(&LocalTransform::new(PrimitiveKind::Tx, 0.4).pose());
        let mut poses: Vec<(Pose, bool)> = PrimitiveKind::ALL
            .into_iter()
            .map(|kind| (LocalTransform::new(kind, 0.7).pose(), true))
            .collect();
        poses.push((parent, false));
        for (pose, primitive) in poses {
            let c = ConstantTransform::new(pose);
            assert_eq!(c.primitive.is_some(), primitive, "{pose:?}");
            assert!(close(&c.ad_inverse(&twist), &pose.ad_inverse(&twist)));
            let mut each = [[0.0; 6]; 2];
            c.ad_inverse_each(&[twist, wrench], &mut each);
            assert!(close(&each[1], &pose.ad_inverse(&wrench)));
            assert!(close(
                &c.wrench_to_parent(&wrench),
                &pose.wrench_to_parent(&wrench)
            ));
            let h = [0.2, -0.1, 0.4];
            assert!(close(
                &c.moment_to_parent(&h, 1.3),
                &pose.moment_to_parent(&h, 1.3)
            ));
            assert!(close(
                &flat(&c.inertia_to_parent(&inertia)),
                &flat(&pose.inertia_to_parent(&inertia))
            ));
            let (a, b) = (c.compose_onto(&parent), pose.compose_onto(&parent));
            assert!(close(&a.r.concat(), &b.r.concat()) && close(&a.p, &b.p));
        }
    }
}
