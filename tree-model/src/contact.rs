//! Unilateral rows: joint limits, a ground half-space, contact spheres on frames and slack
//! strings (docs/derivations.md §13). Each becomes a gap `φ(q) ≥ 0` — a row the variational
//! integrator holds non-negative with a non-negative impulse — and a contact with the ground
//! with friction adds two tangent rows, the coordinates of its centre along two world
//! directions orthogonal to the ground's normal.

use std::collections::HashMap;

use crate::error::{ModelError, Problem, Section, Site};
use crate::model::{Constraint, ConstraintKind, Joint, Model, Parameter, Variable};

/// The ground and contact spheres as written (`[ground]`, `[[contact]]`), and whether the
/// variables' limits are enforced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactsSpec {
    /// Whether declared joint limits are enforced (default: they are; docs/model-format.md).
    pub enforce_limits: Option<bool>,
    /// The ground, if any.
    pub ground: Option<GroundSpec>,
    /// The contact spheres.
    pub contacts: Vec<ContactSpec>,
}

/// A `[ground]` as written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GroundSpec {
    /// The plane's height along its normal (default 0).
    pub height: Option<f64>,
    /// Its normal in world axes (default +z).
    pub normal: Option<[f64; 3]>,
    /// The Coulomb coefficient μ (default 0, frictionless).
    pub friction: Option<f64>,
}

/// A `[[contact]]` as written: a sphere on a frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactSpec {
    /// Name (default `contact<n>`).
    pub name: Option<String>,
    /// The frame at the sphere's centre.
    pub frame: String,
    /// Radius (default 0: a point).
    pub radius: Option<f64>,
    /// Its own Coulomb coefficient (against the ground the smaller of it and the ground's).
    pub friction: Option<f64>,
    /// Whether it touches other contacts (default true); it always touches the ground.
    pub collide: Option<bool>,
}

impl ContactSpec {
    /// A contact as the command line's `--contact` and Python's `with_contacts` write it:
    /// `FRAME` (a point) or `FRAME:RADIUS`, named after its frame; the rest as a model says.
    ///
    /// ```
    /// let c = tree_model::ContactSpec::parse("FL_FOOT:0.016").unwrap();
    /// assert_eq!((c.frame.as_str(), c.radius), ("FL_FOOT", Some(0.016)));
    /// assert!(tree_model::ContactSpec::parse("FL_FOOT:wide").is_err());
    /// ```
    pub fn parse(text: &str) -> Result<ContactSpec, String> {
        let (frame, radius) = match text.split_once(':') {
            Some((f, r)) => {
                let radius = r.trim().parse::<f64>().map_err(|_| {
                    format!(
                        "contact `{text}`: the radius after `:` must be a number (metres), got `{}`",
                        r.trim()
                    )
                })?;
                (f, Some(radius))
            }
            None => (text, None),
        };
        Ok(ContactSpec {
            frame: frame.trim().to_string(),
            radius,
            ..Default::default()
        })
    }
}

/// The half-space `n·x ≥ height` under the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ground {
    /// Height along `normal`.
    pub height: f64,
    /// Unit normal in world axes.
    pub normal: [f64; 3],
    /// Coulomb coefficient μ ≥ 0.
    pub friction: f64,
}

/// A sphere on a frame that meets the ground and other spheres.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSphere {
    /// Unique name.
    pub name: String,
    /// The frame at its centre (index into [`Model::frames`]).
    pub frame: usize,
    /// Radius ≥ 0.
    pub radius: f64,
    /// Its own Coulomb coefficient, if given.
    pub friction: Option<f64>,
    /// Whether it touches other contacts.
    pub collide: bool,
}

/// Everything unilateral in a model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Contacts {
    /// Whether the dynamic variables' limits are rows.
    pub enforce_limits: bool,
    /// The ground, if any.
    pub ground: Option<Ground>,
    /// The contact spheres.
    pub spheres: Vec<ContactSphere>,
    /// Slack strings: distance constraints `‖p_a − p_b‖ ≤ ℓ` (`slack = true`).
    pub strings: Vec<Constraint>,
}

/// What a gap measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GapKind {
    /// `φ = q_i − lo`.
    Lower {
        /// Index into [`Model::variables`].
        variable: usize,
        /// The lower limit.
        bound: f64,
    },
    /// `φ = hi − q_i`.
    Upper {
        /// Index into [`Model::variables`].
        variable: usize,
        /// The upper limit.
        bound: f64,
    },
    /// `φ = n·p_f − height − r`; with friction, tangent rows `t_k·p_f` follow.
    Ground {
        /// The sphere's frame.
        frame: usize,
        /// Its radius.
        radius: f64,
        /// The ground.
        ground: Ground,
        /// Two unit world directions orthogonal to the normal and to each other.
        tangents: [[f64; 3]; 2],
    },
    /// `φ = ‖p_a − p_b‖ − r_a − r_b`.
    Spheres {
        /// The spheres' frames.
        frames: [usize; 2],
        /// `r_a + r_b`.
        radii: f64,
    },
    /// `φ = ℓ − ‖p_a − p_b‖`.
    String {
        /// The string's ends.
        frames: [usize; 2],
        /// Its length.
        length: Parameter,
    },
}

/// One unilateral element: a gap and, for a ground contact with friction, its tangent rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Gap {
    /// The row's name (a limit's `variable.lower`, a contact's name, `a|b` for two spheres,
    /// a string's constraint name).
    pub name: String,
    /// What it measures.
    pub kind: GapKind,
    /// Coulomb coefficient (0: frictionless; only a ground contact has friction).
    pub friction: f64,
}

impl Gap {
    /// Rows it adds: the gap, then two tangent rows when it has friction.
    pub fn rows(&self) -> usize {
        if self.friction > 0.0 {
            3
        } else {
            1
        }
    }

    /// The frames it attaches to.
    pub fn frames(&self) -> Vec<usize> {
        match self.kind {
            GapKind::Lower { .. } | GapKind::Upper { .. } => Vec::new(),
            GapKind::Ground { frame, .. } => vec![frame],
            GapKind::Spheres { frames, .. } | GapKind::String { frames, .. } => frames.to_vec(),
        }
    }
}

/// Two unit vectors orthogonal to unit `n` and to each other: `t₁ ∝ n × e` for the world axis
/// `e` least aligned with `n`, `t₂ = n × t₁`.
pub fn tangents(n: &[f64; 3]) -> [[f64; 3]; 2] {
    let k = (0..3)
        .min_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[k] = 1.0;
    let t1 = normalized(cross(n, &e));
    [t1, cross(n, &t1)]
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalized(v: [f64; 3]) -> [f64; 3] {
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / norm)
}

impl Model {
    /// Every unilateral element in row order: the dynamic variables' limits (when enforced,
    /// lower then upper), each sphere against the ground, each pair of colliding spheres on
    /// different bodies, then the slack strings.
    pub fn gaps(&self) -> Vec<Gap> {
        let c = &self.contacts;
        let mut gaps = Vec::new();
        if c.enforce_limits {
            for (i, v) in self.variables.iter().enumerate() {
                if let (Some([lo, hi]), false) = (v.limits, v.is_kinematic()) {
                    gaps.push(limit_gap(v, i, lo, false));
                    gaps.push(limit_gap(v, i, hi, true));
                }
            }
        }
        if let Some(ground) = c.ground {
            for s in &c.spheres {
                let friction = s
                    .friction
                    .map_or(ground.friction, |f| f.min(ground.friction));
                gaps.push(Gap {
                    name: s.name.clone(),
                    kind: GapKind::Ground {
                        frame: s.frame,
                        radius: s.radius,
                        ground,
                        tangents: tangents(&ground.normal),
                    },
                    friction,
                });
            }
        }
        let bodies: Vec<Option<usize>> = c.spheres.iter().map(|s| self.body_of(s.frame)).collect();
        for (x, a) in c.spheres.iter().enumerate() {
            for (y, b) in c.spheres.iter().enumerate().skip(x + 1) {
                if a.collide && b.collide && bodies[x] != bodies[y] {
                    gaps.push(Gap {
                        name: format!("{}|{}", a.name, b.name),
                        kind: GapKind::Spheres {
                            frames: [a.frame, b.frame],
                            radii: a.radius + b.radius,
                        },
                        friction: 0.0,
                    });
                }
            }
        }
        for s in &c.strings {
            if let ConstraintKind::Distance { length } = s.kind {
                gaps.push(Gap {
                    name: s.name.clone(),
                    kind: GapKind::String {
                        frames: s.frames,
                        length,
                    },
                    friction: 0.0,
                });
            }
        }
        gaps
    }

    /// Number of unilateral rows ([`Gap::rows`] summed).
    pub fn gap_rows(&self) -> usize {
        self.gaps().iter().map(Gap::rows).sum()
    }

    /// The rigid body frame `f` belongs to: its nearest ancestor-or-self driven by a
    /// variable (`None`: fixed to the world).
    pub fn body_of(&self, f: usize) -> Option<usize> {
        let mut k = Some(f);
        while let Some(i) = k {
            if !matches!(self.frames[i].joint, Joint::Constant(_)) {
                return Some(i);
            }
            k = self.frames[i].parent;
        }
        None
    }
}

impl Model {
    /// This model with `extra`'s ground (replacing its own), contact spheres (after its own)
    /// and limits setting (when given): what a user adds to a model without editing it (the
    /// CLI's `--ground`, `--contact`, `--limits`). An added sphere without a name takes its
    /// frame's. Problems as a model's, each naming its entry.
    ///
    /// ```
    /// use tree_model::{ContactSpec, ContactsSpec, GroundSpec};
    /// let arm = tree_model::n_link_pendulum(2);
    /// let extra = ContactsSpec {
    ///     ground: Some(GroundSpec { height: Some(-2.5), ..Default::default() }),
    ///     contacts: vec![ContactSpec { frame: "link2".into(), radius: Some(0.05), ..Default::default() }],
    ///     ..Default::default()
    /// };
    /// let model = arm.with_contacts(&extra).unwrap();
    /// assert_eq!(model.gaps().len(), 1);
    /// ```
    pub fn with_contacts(&self, extra: &ContactsSpec) -> Result<Model, ModelError> {
        let index_of: HashMap<&str, usize> = (self.frames.iter().enumerate())
            .map(|(k, f)| (f.name.as_str(), k))
            .collect();
        let mut problems = Vec::new();
        let (ground, spheres) = validate_contacts(extra, &index_of, &mut problems);
        let mut model = self.clone();
        let c = &mut model.contacts;
        // An added sphere without a name is named after its frame.
        for (mut s, e) in spheres.into_iter().zip(&extra.contacts) {
            if e.name.is_none() {
                s.name = e.frame.clone();
            }
            if c.spheres.iter().any(|o| o.name == s.name) {
                problems.push(Problem {
                    site: Site::Model,
                    message: format!("a contact named `{}` is in the model already", s.name),
                    line: None,
                });
            }
            c.spheres.push(s);
        }
        if ground.is_some() {
            c.ground = ground;
        }
        if let Some(enforce) = extra.enforce_limits {
            c.enforce_limits = enforce;
        }
        match problems.is_empty() {
            true => Ok(model),
            false => Err(ModelError {
                source_name: None,
                problems,
            }),
        }
    }
}

fn limit_gap(v: &Variable, i: usize, bound: f64, upper: bool) -> Gap {
    let (kind, side) = if upper {
        (GapKind::Upper { variable: i, bound }, "upper")
    } else {
        (GapKind::Lower { variable: i, bound }, "lower")
    };
    Gap {
        name: format!("{}.{side}", v.name),
        kind,
        friction: 0.0,
    }
}

/// Checks the ground and the contact spheres (each problem at its entry and field).
pub(crate) fn validate_contacts(
    spec: &ContactsSpec,
    index_of: &HashMap<&str, usize>,
    problems: &mut Vec<Problem>,
) -> (Option<Ground>, Vec<ContactSphere>) {
    let ground = spec.ground.as_ref().map(|g| ground_of(g, problems));
    let mut spheres = Vec::new();
    let mut names: HashMap<String, usize> = HashMap::new();
    for (index, c) in spec.contacts.iter().enumerate() {
        let mut at = |field: &'static str, message: String| {
            problems.push(Problem {
                site: Site::Element {
                    section: Section::Contact,
                    index,
                    field: Some(field),
                },
                message,
                line: None,
            })
        };
        let name = c
            .name
            .clone()
            .unwrap_or_else(|| format!("contact{}", index + 1));
        let what = format!("contact `{name}`");
        if let Some(first) = names.insert(name.clone(), index) {
            at(
                "name",
                format!(
                    "duplicate contact name `{name}` (contacts {} and {} of the list)",
                    first + 1,
                    index + 1
                ),
            );
        }
        let radius = c.radius.unwrap_or(0.0);
        if !(radius.is_finite() && radius >= 0.0) {
            at(
                "radius",
                format!("{what}: radius {radius} must be finite and not negative"),
            );
        }
        if let Some(mu) = c.friction.filter(|mu| !(mu.is_finite() && *mu >= 0.0)) {
            at(
                "friction",
                format!("{what}: friction {mu} must be finite and not negative"),
            );
        }
        let frame = match index_of.get(c.frame.as_str()) {
            Some(&k) => Some(k),
            None if c.frame == "world" => {
                at(
                    "frame",
                    format!("{what} is on the world frame, which never moves: put it on a frame of the tree"),
                );
                None
            }
            None => {
                at("frame", format!("{what}: unknown frame `{}`", c.frame));
                None
            }
        };
        if let Some(frame) = frame {
            spheres.push(ContactSphere {
                name,
                frame,
                radius,
                friction: c.friction,
                collide: c.collide.unwrap_or(true),
            });
        }
    }
    (ground, spheres)
}

/// The ground with its normal made unit.
fn ground_of(g: &GroundSpec, problems: &mut Vec<Problem>) -> Ground {
    let mut at = |field: &'static str, message: String| {
        problems.push(Problem {
            site: Site::Element {
                section: Section::Ground,
                index: 0,
                field: Some(field),
            },
            message,
            line: None,
        })
    };
    let height = g.height.unwrap_or(0.0);
    if !height.is_finite() {
        at("height", format!("ground: height {height} must be finite"));
    }
    let friction = g.friction.unwrap_or(0.0);
    if !(friction.is_finite() && friction >= 0.0) {
        at(
            "friction",
            format!("ground: friction {friction} must be finite and not negative"),
        );
    }
    let n = g.normal.unwrap_or([0.0, 0.0, 1.0]);
    let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let normal = if norm.is_finite() && norm > 0.0 {
        n.map(|x| x / norm)
    } else {
        at(
            "normal",
            format!(
                "ground: normal [{}, {}, {}] must be finite and not zero",
                n[0], n[1], n[2]
            ),
        );
        [0.0, 0.0, 1.0]
    };
    Ground {
        height,
        normal,
        friction,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangents_are_orthonormal_to_the_normal() {
        for n in [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [1.0, 0.0, 0.0]] {
            let [t1, t2] = tangents(&n);
            let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            for (a, b, want) in [
                (&t1, &n, 0.0),
                (&t2, &n, 0.0),
                (&t1, &t2, 0.0),
                (&t1, &t1, 1.0),
                (&t2, &t2, 1.0),
            ] {
                assert!((dot(a, b) - want).abs() < 1e-15, "{n:?}");
            }
            // Right-handed: t₁ × t₂ = n.
            let c = cross(&t1, &t2);
            assert!((dot(&c, &n) - 1.0).abs() < 1e-15);
        }
    }
}
