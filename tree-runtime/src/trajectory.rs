//! A simulated trajectory: times, configurations, velocities, momenta (VI), energy, and with
//! constraints their forces and violation; and the CSV it writes, whole or streamed.

use std::io::{self, Write};

/// One recorded state, as an integrator hands it out.
#[derive(Clone, Copy, Debug)]
pub struct Sample<'a> {
    /// Step index (0: the start).
    pub step: usize,
    /// Time, s.
    pub t: f64,
    /// Configuration.
    pub q: &'a [f64],
    /// Velocity.
    pub dq: &'a [f64],
    /// The VI's discrete momentum.
    pub p: Option<&'a [f64]>,
    /// `T + V` (springs included); not conserved while kinematic inputs move.
    pub energy: f64,
    /// Constraint forces `λ`, one per constraint equation.
    pub lambda: &'a [f64],
    /// `max |h_r(q)|`.
    pub violation: f64,
    /// The system's inputs in force from this sample on (empty without inputs).
    pub u: &'a [f64],
    /// Each unilateral row's impulse over the step that ended here (γ, or a friction
    /// component at a tangent row; N·s) — empty without unilateral rows (docs §13).
    pub impulse: &'a [f64],
    /// Each unilateral row's value here (a gap in m or rad; a tangent row's coordinate).
    pub gap: &'a [f64],
}

/// One run's output, stored row by row in flat vectors (`dof` values a row).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Variable names, in order.
    pub variables: Vec<String>,
    /// Constraint equation names, in order.
    pub constraints: Vec<String>,
    /// Time of each sample.
    pub t: Vec<f64>,
    q: Vec<f64>,
    dq: Vec<f64>,
    p: Vec<f64>,
    lambda: Vec<f64>,
    /// Total energy `E = T + V` at each sample.
    pub energy: Vec<f64>,
    /// The inputs in force from each sample on, row after row (empty without inputs).
    u: Vec<f64>,
    /// `max |h|` at each sample.
    pub violation: Vec<f64>,
    /// The unilateral rows' names (a limit's `variable.lower`, a contact's name with `.t1`,
    /// `.t2` for its tangent rows, `a|b` for two spheres, a slack string's).
    pub unilateral: Vec<String>,
    impulse: Vec<f64>,
    gap: Vec<f64>,
    /// Total Newton iterations (VI only).
    pub newton_iterations: usize,
    /// Steps the VI had to subdivide.
    pub subdivided_steps: usize,
    /// The energy the model's damping and dampers took out over the run (see
    /// [`crate::integrate::RunSummary::dissipated`]).
    pub dissipated: f64,
}

impl Trajectory {
    /// Empty, with room for `capacity` samples.
    pub fn new(variables: Vec<String>, constraints: Vec<String>, capacity: usize) -> Self {
        let n = variables.len();
        Trajectory {
            t: Vec::with_capacity(capacity),
            q: Vec::with_capacity(capacity * n),
            dq: Vec::with_capacity(capacity * n),
            energy: Vec::with_capacity(capacity),
            variables,
            constraints,
            ..Default::default()
        }
    }

    /// Number of variables.
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether no sample was recorded.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Appends a sample.
    pub fn push(&mut self, s: &Sample) {
        self.t.push(s.t);
        self.q.extend_from_slice(s.q);
        self.dq.extend_from_slice(s.dq);
        if let Some(p) = s.p {
            self.p.extend_from_slice(p);
        }
        self.lambda.extend_from_slice(s.lambda);
        self.energy.push(s.energy);
        self.violation.push(s.violation);
        self.u.extend_from_slice(s.u);
        self.impulse.extend_from_slice(s.impulse);
        self.gap.extend_from_slice(s.gap);
    }

    /// Each unilateral row's impulse over the step that ended at sample `k` (zero at the
    /// start; empty without unilateral rows).
    pub fn impulse(&self, k: usize) -> &[f64] {
        let r = self.unilateral.len();
        &self.impulse[k * r..(k + 1) * r]
    }

    /// Each unilateral row's value at sample `k` (the gaps; empty without unilateral rows).
    pub fn gap(&self, k: usize) -> &[f64] {
        let r = self.unilateral.len();
        &self.gap[k * r..(k + 1) * r]
    }

    /// Configuration of sample `k`.
    pub fn q(&self, k: usize) -> &[f64] {
        let n = self.dof();
        &self.q[k * n..(k + 1) * n]
    }

    /// Velocity of sample `k`.
    pub fn dq(&self, k: usize) -> &[f64] {
        let n = self.dof();
        &self.dq[k * n..(k + 1) * n]
    }

    /// Every sample's configuration, row after row (`dof` values a row).
    pub fn q_rows(&self) -> &[f64] {
        &self.q
    }

    /// Every sample's velocity, row after row.
    pub fn dq_rows(&self) -> &[f64] {
        &self.dq
    }

    /// The VI's momentum at sample k, when recorded.
    pub fn p(&self, k: usize) -> Option<&[f64]> {
        let n = self.dof();
        (self.p.len() >= (k + 1) * n).then(|| &self.p[k * n..(k + 1) * n])
    }

    /// The inputs in force from sample k on (empty when the run had none).
    pub fn u(&self, k: usize) -> &[f64] {
        let w = self.u.len() / self.len().max(1);
        &self.u[k * w..(k + 1) * w]
    }

    /// The constraint forces at sample k.
    pub fn lambda(&self, k: usize) -> &[f64] {
        let m = self.constraints.len();
        &self.lambda[k * m..(k + 1) * m]
    }

    /// The last sample's configuration.
    pub fn last_q(&self) -> &[f64] {
        self.q(self.len() - 1)
    }

    /// Largest `|E_k − E_0|` over the samples: the integrator's energy error for a
    /// conservative model (no damping, dampers or moving kinematic inputs). With damping the
    /// energy falls by [`Self::dissipated`]; the error is then `E_end − E_0 + dissipated`.
    pub fn max_energy_error(&self) -> f64 {
        let e0 = self.energy.first().copied().unwrap_or(0.0);
        self.energy.iter().fold(0.0, |m, e| m.max((e - e0).abs()))
    }

    /// Largest constraint violation over the run.
    pub fn worst_violation(&self) -> f64 {
        self.violation.iter().fold(0.0, |m: f64, v| m.max(*v))
    }

    /// Writes the whole trajectory as CSV (see [`CsvStream`]).
    pub fn write_csv(&self, w: impl Write) -> io::Result<()> {
        let mut csv =
            CsvStream::with_all(w, &self.variables, &self.constraints, &[], &self.unilateral)?;
        for k in 0..self.len() {
            csv.write(&Sample {
                step: k,
                t: self.t[k],
                q: self.q(k),
                dq: self.dq(k),
                p: self.p(k),
                energy: self.energy[k],
                lambda: self.lambda(k),
                violation: self.violation[k],
                u: &[],
                impulse: self.impulse(k),
                gap: self.gap(k),
            })?;
        }
        csv.finish()
    }
}

/// CSV rows written as samples arrive: header `t,<var…>,d<var…>,energy`, then with
/// constraints `lambda_<constraint…>,violation`.
pub struct CsvStream<W: Write> {
    out: W,
    constraints: bool,
    /// Columns `impulse_<row>` and `gap_<row>` per unilateral row.
    unilateral: usize,
    /// Columns `u_<input>` at the end.
    inputs: usize,
}

impl<W: Write> CsvStream<W> {
    /// Writes the header to `out`.
    pub fn new(out: W, variables: &[String], constraints: &[String]) -> io::Result<Self> {
        Self::with_inputs(out, variables, constraints, &[])
    }

    /// Writes the header to `out`, with a column `u_<name>` per input at the end.
    pub fn with_inputs(
        out: W,
        variables: &[String],
        constraints: &[String],
        inputs: &[String],
    ) -> io::Result<Self> {
        Self::with_all(out, variables, constraints, inputs, &[])
    }

    /// Writes the header to `out`, with columns `impulse_<row>`, `gap_<row>` per unilateral
    /// row after the constraints' and `u_<name>` per input at the end.
    pub fn with_all(
        mut out: W,
        variables: &[String],
        constraints: &[String],
        inputs: &[String],
        unilateral: &[String],
    ) -> io::Result<Self> {
        let header = csv_header(variables, constraints, inputs, unilateral)?;
        let header: Vec<String> = header.iter().map(|h| csv_field(h)).collect();
        writeln!(out, "{}", header.join(","))?;
        Ok(CsvStream {
            out,
            constraints: !constraints.is_empty(),
            unilateral: unilateral.len(),
            inputs: inputs.len(),
        })
    }

    /// Writes one sample as a CSV row, each number in its shortest form that reads back
    /// exactly (ryu: the formatting was a third of a recorded VI step).
    pub fn write(&mut self, s: &Sample) -> io::Result<()> {
        let mut buf = ryu::Buffer::new();
        let out = &mut self.out;
        out.write_all(buf.format(s.t).as_bytes())?;
        let lambda = if self.constraints { s.lambda } else { &[] };
        for &x in
            s.q.iter()
                .chain(s.dq)
                .chain([s.energy].iter())
                .chain(lambda)
        {
            out.write_all(b",")?;
            out.write_all(buf.format(x).as_bytes())?;
        }
        if self.constraints {
            out.write_all(b",")?;
            out.write_all(buf.format(s.violation).as_bytes())?;
        }
        for column in [s.impulse, s.gap] {
            for k in 0..self.unilateral {
                out.write_all(b",")?;
                out.write_all(buf.format(column.get(k).copied().unwrap_or(0.0)).as_bytes())?;
            }
        }
        for k in 0..self.inputs {
            out.write_all(b",")?;
            out.write_all(buf.format(s.u.get(k).copied().unwrap_or(0.0)).as_bytes())?;
        }
        out.write_all(b"\n")
    }

    /// Flushes the output.
    pub fn finish(mut self) -> io::Result<()> {
        self.out.flush()
    }
}

/// The trajectory's column names — `t`, each variable, `d` + each variable, `energy`,
/// `lambda_` + each constraint row, `violation` (with constraints), `impulse_` and `gap_` + each
/// unilateral row, `u_` + each input — or an
/// `InvalidInput` error naming the first two columns that would bear one name (a variable `t`,
/// or `theta` beside a variable `dtheta`), so that a reader can never take one for the other.
fn csv_header(
    variables: &[String],
    constraints: &[String],
    inputs: &[String],
    unilateral: &[String],
) -> io::Result<Vec<String>> {
    let mut named: Vec<(String, String)> = vec![("t".into(), "the time".into())];
    named.extend(
        variables
            .iter()
            .map(|v| (v.clone(), format!("variable `{v}`"))),
    );
    named.extend(
        variables
            .iter()
            .map(|v| (format!("d{v}"), format!("the velocity of `{v}`"))),
    );
    named.push(("energy".into(), "the energy".into()));
    named.extend(constraints.iter().map(|c| {
        (
            format!("lambda_{c}"),
            format!("the force of constraint `{c}`"),
        )
    }));
    if !constraints.is_empty() {
        named.push(("violation".into(), "the constraint violation".into()));
    }
    for (prefix, what) in [("impulse", "the impulse"), ("gap", "the gap")] {
        named.extend(
            (unilateral.iter()).map(|r| (format!("{prefix}_{r}"), format!("{what} of `{r}`"))),
        );
    }
    named.extend(
        inputs
            .iter()
            .map(|u| (format!("u_{u}"), format!("input `{u}`"))),
    );
    let mut seen: std::collections::HashMap<&str, &str> = std::collections::HashMap::new();
    for (name, what) in &named {
        if let Some(first) = seen.insert(name, what) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "the trajectory's columns for {first} and {what} would both be named \
                     `{name}`: rename one (a CSV column must name one thing)"
                ),
            ));
        }
    }
    Ok(named.into_iter().map(|(name, _)| name).collect())
}

/// A CSV field as RFC 4180 writes it: quoted, with quotes doubled, when it holds a comma, a
/// quote or a line break.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}
