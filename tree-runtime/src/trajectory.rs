//! A simulated trajectory: times, configurations, velocities, momenta (VI) and energy.

use std::io::{self, Write};

/// One run's output, stored row by row in flat vectors (`dof` values a row).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Variable names, in order.
    pub variables: Vec<String>,
    pub t: Vec<f64>,
    q: Vec<f64>,
    dq: Vec<f64>,
    p: Vec<f64>,
    /// Total energy `E = T + V` at each sample.
    pub energy: Vec<f64>,
    /// Total Newton iterations (VI only).
    pub newton_iterations: usize,
}

impl Trajectory {
    pub fn new(variables: Vec<String>, capacity: usize) -> Self {
        let n = variables.len();
        Trajectory {
            variables,
            t: Vec::with_capacity(capacity),
            q: Vec::with_capacity(capacity * n),
            dq: Vec::with_capacity(capacity * n),
            p: Vec::new(),
            energy: Vec::with_capacity(capacity),
            newton_iterations: 0,
        }
    }

    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Appends a sample; `p` is the discrete momentum for the VI.
    pub fn push(&mut self, t: f64, q: &[f64], dq: &[f64], p: Option<&[f64]>, energy: f64) {
        self.t.push(t);
        self.q.extend_from_slice(q);
        self.dq.extend_from_slice(dq);
        if let Some(p) = p {
            self.p.extend_from_slice(p);
        }
        self.energy.push(energy);
    }

    pub fn q(&self, k: usize) -> &[f64] {
        let n = self.dof();
        &self.q[k * n..(k + 1) * n]
    }

    pub fn dq(&self, k: usize) -> &[f64] {
        let n = self.dof();
        &self.dq[k * n..(k + 1) * n]
    }

    /// The VI's momentum at sample k, when recorded.
    pub fn p(&self, k: usize) -> Option<&[f64]> {
        let n = self.dof();
        (self.p.len() >= (k + 1) * n).then(|| &self.p[k * n..(k + 1) * n])
    }

    /// The last sample's configuration.
    pub fn last_q(&self) -> &[f64] {
        self.q(self.len() - 1)
    }

    /// Largest `|E_k − E_0|`.
    pub fn max_energy_error(&self) -> f64 {
        let e0 = self.energy.first().copied().unwrap_or(0.0);
        self.energy.iter().fold(0.0, |m, e| m.max((e - e0).abs()))
    }

    /// CSV with header `t,<var…>,d<var…>,energy`.
    pub fn write_csv(&self, mut w: impl Write) -> io::Result<()> {
        let mut header = vec!["t".to_string()];
        header.extend(self.variables.iter().cloned());
        header.extend(self.variables.iter().map(|v| format!("d{v}")));
        header.push("energy".into());
        writeln!(w, "{}", header.join(","))?;
        for k in 0..self.len() {
            write!(w, "{}", self.t[k])?;
            for x in self.q(k).iter().chain(self.dq(k)) {
                write!(w, ",{x}")?;
            }
            writeln!(w, ",{}", self.energy[k])?;
        }
        Ok(())
    }
}
