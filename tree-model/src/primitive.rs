//! The six primitive transforms a frame can hang off its parent by (paper §III, assumption 1).

use std::fmt;

/// One of the six primitive rigid transforms: translation along, or rotation about, one of
/// the parent frame's axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PrimitiveKind {
    /// Translation along x.
    Tx,
    /// Translation along y.
    Ty,
    /// Translation along z.
    Tz,
    /// Rotation about x.
    Rx,
    /// Rotation about y.
    Ry,
    /// Rotation about z.
    Rz,
}

impl PrimitiveKind {
    /// All six, in the order `tx ty tz rx ry rz`.
    pub const ALL: [PrimitiveKind; 6] = [
        PrimitiveKind::Tx,
        PrimitiveKind::Ty,
        PrimitiveKind::Tz,
        PrimitiveKind::Rx,
        PrimitiveKind::Ry,
        PrimitiveKind::Rz,
    ];

    /// The keyword used in TOML files and in `tree_model!`.
    pub fn keyword(self) -> &'static str {
        match self {
            PrimitiveKind::Tx => "tx",
            PrimitiveKind::Ty => "ty",
            PrimitiveKind::Tz => "tz",
            PrimitiveKind::Rx => "rx",
            PrimitiveKind::Ry => "ry",
            PrimitiveKind::Rz => "rz",
        }
    }

    /// Parses a keyword (`"rx"` …); `None` for anything else.
    pub fn from_keyword(word: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.keyword() == word)
    }

    /// True for `rx ry rz`.
    pub fn is_rotation(self) -> bool {
        matches!(
            self,
            PrimitiveKind::Rx | PrimitiveKind::Ry | PrimitiveKind::Rz
        )
    }

    /// The axis index 0, 1, 2 for X, Y, Z.
    pub fn axis(self) -> usize {
        match self {
            PrimitiveKind::Tx | PrimitiveKind::Rx => 0,
            PrimitiveKind::Ty | PrimitiveKind::Ry => 1,
            PrimitiveKind::Tz | PrimitiveKind::Rz => 2,
        }
    }

    /// The constant unit twist ξ with `g(x) = exp(ξ̂ x)`, ordered `(v, ω)`.
    pub fn twist(self) -> [f64; 6] {
        let mut xi = [0.0; 6];
        let offset = if self.is_rotation() { 3 } else { 0 };
        xi[offset + self.axis()] = 1.0;
        xi
    }
}

impl fmt::Display for PrimitiveKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.keyword())
    }
}

/// What a primitive's parameter is: a constant, or a named configuration variable.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A fixed parameter (m or rad).
    Constant(f64),
    /// Driven by the configuration variable of this name.
    Variable(String),
    /// Following the variable of another frame: `multiplier·q + offset` (a mimic joint).
    Mimic(MimicSpec),
}

/// A mimic transform as written: the variable it follows, by name, and the affine map.
#[derive(Clone, Debug, PartialEq)]
pub struct MimicSpec {
    /// The variable followed.
    pub variable: String,
    /// `∂x/∂q` (default 1).
    pub multiplier: f64,
    /// `x` at `q = 0` (default 0).
    pub offset: f64,
    /// Viscous damping on the follower's own motion (default 0).
    pub damping: f64,
}

impl MimicSpec {
    /// Following `variable` one to one.
    pub fn new(variable: impl Into<String>) -> Self {
        MimicSpec {
            variable: variable.into(),
            multiplier: 1.0,
            offset: 0.0,
            damping: 0.0,
        }
    }
}

impl From<MimicSpec> for Value {
    fn from(m: MimicSpec) -> Self {
        Value::Mimic(m)
    }
}

impl From<f64> for Value {
    fn from(x: f64) -> Self {
        Value::Constant(x)
    }
}

impl From<&str> for Value {
    fn from(name: &str) -> Self {
        Value::Variable(name.to_string())
    }
}

/// A primitive transform together with its parameter, as written in a model.
#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    /// Which primitive.
    pub kind: PrimitiveKind,
    /// Its parameter.
    pub value: Value,
}

impl Primitive {
    /// `kind` with `value` (a number or a variable name).
    pub fn new(kind: PrimitiveKind, value: impl Into<Value>) -> Self {
        Primitive {
            kind,
            value: value.into(),
        }
    }
}
