//! Model errors: every problem found, each naming the thing at fault and where it is.

use std::fmt;

/// Which part of a frame a problem is about (lets TOML point at a line and the macro at a token).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameField {
    /// The frame as a whole.
    Whole,
    /// Its `name`.
    Name,
    /// Its `parent`.
    Parent,
    /// Its primitive (`tx` … `rz`) and parameter.
    Primitive,
    /// Its `mass`.
    Mass,
    /// Its `inertia`.
    Inertia,
    /// Its centre of mass, `com`.
    Com,
}

/// Where in a model a problem sits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Site {
    /// The model as a whole (no variables, a syntax error, a missing file).
    Model,
    /// The model's `gravity`.
    Gravity,
    /// The frame at this position of the specification's frame list.
    Frame {
        /// Position in the frame list.
        index: usize,
        /// The part of the frame at fault.
        field: FrameField,
    },
    /// The settings of the variable of this name.
    VariableSettings {
        /// The variable's name.
        name: String,
    },
    /// A constraint, spring or damper (by position in its list) and the field at fault
    /// (`None`: the whole entry).
    Element {
        /// Which list.
        section: Section,
        /// Position in that list.
        index: usize,
        /// The field at fault (`None`: the whole entry).
        field: Option<&'static str>,
    },
}

/// The lists of elements a model has besides its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Section {
    /// `[[constraint]]`
    Constraint,
    /// `[[spring]]`
    Spring,
    /// `[[damper]]`
    Damper,
    /// `[[input]]`
    Input,
    /// `[[contact]]`
    Contact,
    /// `[ground]` (one, index 0)
    Ground,
}

impl Section {
    /// The TOML table name (`constraint`, `spring`, `damper`).
    pub fn keyword(self) -> &'static str {
        match self {
            Section::Constraint => "constraint",
            Section::Spring => "spring",
            Section::Damper => "damper",
            Section::Input => "input",
            Section::Contact => "contact",
            Section::Ground => "ground",
        }
    }
}

/// One problem with a model.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// Where the problem is.
    pub site: Site,
    /// What is wrong, naming the thing at fault.
    pub message: String,
    /// 1-based line in the source text, when the model came from one (a file or a string).
    pub line: Option<usize>,
}

/// Everything wrong with a model, collected before failing.
#[derive(Clone, PartialEq)]
pub struct ModelError {
    /// The file the model came from, if any.
    pub source_name: Option<String>,
    /// Every problem found, in the order found.
    pub problems: Vec<Problem>,
}

impl ModelError {
    pub(crate) fn single(
        source_name: Option<String>,
        message: String,
        line: Option<usize>,
    ) -> Self {
        ModelError {
            source_name,
            problems: vec![Problem {
                site: Site::Model,
                message,
                line,
            }],
        }
    }
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (n, p) in self.problems.iter().enumerate() {
            if n > 0 {
                writeln!(f)?;
            }
            match (&self.source_name, p.line) {
                (Some(file), Some(line)) => write!(f, "{file}:{line}: {}", p.message)?,
                (Some(file), None) => write!(f, "{file}: {}", p.message)?,
                (None, Some(line)) => write!(f, "line {line}: {}", p.message)?,
                (None, None) => write!(f, "{}", p.message)?,
            }
        }
        Ok(())
    }
}

/// The message itself, so `fn main() -> Result<(), Box<dyn Error>>` (which prints an
/// error with `{:?}`) shows the sentence, not the struct.
impl fmt::Debug for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl std::error::Error for ModelError {}
