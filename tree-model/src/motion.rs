//! Prescribed motions of kinematic variables: `t ↦ (q, q̇, q̈)`.

/// How a kinematic variable moves, as a model file prescribes it.
#[derive(Clone, Debug, PartialEq)]
pub enum Motion {
    /// `q = q0 + dq0·t` (held at `q0` when `dq0 = 0`).
    Steady {
        /// Value at t = 0.
        q0: f64,
        /// Constant velocity.
        dq0: f64,
    },
    /// `q = offset + amplitude·sin(2πf t + phase)`.
    Sine {
        /// Mean value.
        offset: f64,
        /// Amplitude.
        amplitude: f64,
        /// Frequency f in Hz.
        frequency: f64,
        /// Phase at t = 0, rad.
        phase: f64,
    },
    /// A natural cubic spline through samples `(t, q)` (C²), continued linearly outside them.
    Spline(CubicSpline),
}

impl Motion {
    /// `(q, q̇, q̈)` at time `t`.
    pub fn at(&self, t: f64) -> [f64; 3] {
        match self {
            Motion::Steady { q0, dq0 } => [q0 + dq0 * t, *dq0, 0.0],
            Motion::Sine {
                offset,
                amplitude,
                frequency,
                phase,
            } => {
                let w = 2.0 * std::f64::consts::PI * frequency;
                let (s, c) = (w * t + phase).sin_cos();
                [
                    offset + amplitude * s,
                    amplitude * w * c,
                    -amplitude * w * w * s,
                ]
            }
            Motion::Spline(s) => s.at(t),
        }
    }
}

/// A natural cubic spline: piecewise cubic through every sample, continuous in value, slope
/// and curvature, with zero curvature at both ends (so the linear continuation outside the
/// samples keeps it C²).
#[derive(Clone, Debug, PartialEq)]
pub struct CubicSpline {
    t: Vec<f64>,
    q: Vec<f64>,
    /// Second derivative at each sample.
    curvature: Vec<f64>,
}

impl CubicSpline {
    /// Through `samples` `(t, q)`, strictly increasing in `t`, at least two. The caller
    /// validates (see `validate`); `None` when the samples do not qualify.
    pub fn new(samples: &[[f64; 2]]) -> Option<Self> {
        let n = samples.len();
        if n < 2
            || samples.iter().flatten().any(|x| !x.is_finite())
            || samples.windows(2).any(|w| w[1][0] <= w[0][0])
        {
            return None;
        }
        let t: Vec<f64> = samples.iter().map(|s| s[0]).collect();
        let q: Vec<f64> = samples.iter().map(|s| s[1]).collect();
        // Tridiagonal system for the interior curvatures (Thomas algorithm).
        let mut curvature = vec![0.0; n];
        if n > 2 {
            let m = n - 2;
            let (mut diag, mut rhs) = (vec![0.0; m], vec![0.0; m]);
            let mut upper = vec![0.0; m];
            for i in 1..n - 1 {
                let (h0, h1) = (t[i] - t[i - 1], t[i + 1] - t[i]);
                diag[i - 1] = 2.0 * (h0 + h1);
                upper[i - 1] = h1;
                rhs[i - 1] = 6.0 * ((q[i + 1] - q[i]) / h1 - (q[i] - q[i - 1]) / h0);
            }
            for i in 1..m {
                let lower = t[i + 1] - t[i];
                let w = lower / diag[i - 1];
                diag[i] -= w * upper[i - 1];
                rhs[i] -= w * rhs[i - 1];
            }
            for i in (0..m).rev() {
                let next = if i + 1 < m { curvature[i + 2] } else { 0.0 };
                curvature[i + 1] = (rhs[i] - upper[i] * next) / diag[i];
            }
        }
        // Samples of huge values or tiny spacing: the slopes or curvatures overflow.
        let slopes_finite = (1..n).all(|i| ((q[i] - q[i - 1]) / (t[i] - t[i - 1])).is_finite());
        if !slopes_finite || curvature.iter().any(|c| !c.is_finite()) {
            return None;
        }
        let spline = CubicSpline { t, q, curvature };
        // Samples near the float's limits (±1e308): sums inside a segment can overflow
        // where no sample does. Each segment's ends and middle, and t = 0, must be finite.
        let finite = |t: f64| spline.at(t).iter().all(|x| x.is_finite());
        let inside = spline.t.windows(2).all(|w| {
            let middle = w[0] + 0.5 * (w[1] - w[0]);
            finite(w[0]) && finite(middle) && finite(w[1])
        });
        (inside && finite(0.0)).then_some(spline)
    }

    /// The samples' time span.
    pub fn span(&self) -> (f64, f64) {
        (self.t[0], self.t[self.t.len() - 1])
    }

    /// `(q, q̇, q̈)` at `t`.
    pub fn at(&self, t: f64) -> [f64; 3] {
        let n = self.t.len();
        let (t0, t1) = self.span();
        if t <= t0 || t >= t1 {
            // Linear continuation with the end slope (curvature is zero there).
            let (i, edge) = if t <= t0 { (0, t0) } else { (n - 2, t1) };
            let [q, dq, _] = self.segment(i, edge);
            return [q + dq * (t - edge), dq, 0.0];
        }
        let i = self.t.partition_point(|&x| x <= t).clamp(1, n - 1) - 1;
        self.segment(i, t)
    }

    /// The cubic of segment `[t_i, t_{i+1}]` at `t`.
    fn segment(&self, i: usize, t: f64) -> [f64; 3] {
        let h = self.t[i + 1] - self.t[i];
        let (a, b) = ((self.t[i + 1] - t) / h, (t - self.t[i]) / h);
        let (c0, c1) = (self.curvature[i], self.curvature[i + 1]);
        let (q0, q1) = (self.q[i], self.q[i + 1]);
        let q = a * q0 + b * q1 + ((a * a * a - a) * c0 + (b * b * b - b) * c1) * h * h / 6.0;
        let dq = (q1 - q0) / h + ((1.0 - 3.0 * a * a) * c0 + (3.0 * b * b - 1.0) * c1) * h / 6.0;
        let ddq = a * c0 + b * c1;
        [q, dq, ddq]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spline_interpolates_and_is_c2() {
        let s = CubicSpline::new(&[[0.0, 0.0], [1.0, 1.0], [2.5, -0.5], [3.0, 0.2]]).unwrap();
        for (t, q) in [(0.0, 0.0), (1.0, 1.0), (2.5, -0.5), (3.0, 0.2)] {
            assert!((s.at(t)[0] - q).abs() < 1e-14, "passes through ({t}, {q})");
        }
        // Value, slope and curvature continuous across every knot and both ends.
        for knot in [0.0, 1.0, 2.5, 3.0] {
            let (l, r) = (s.at(knot - 1e-9), s.at(knot + 1e-9));
            for k in 0..3 {
                assert!((l[k] - r[k]).abs() < 1e-6, "derivative {k} jumps at {knot}");
            }
        }
        // Derivatives against finite differences inside a segment.
        let (t, h) = (1.7, 1e-5);
        let d = (s.at(t + h)[0] - s.at(t - h)[0]) / (2.0 * h);
        let dd = (s.at(t + h)[1] - s.at(t - h)[1]) / (2.0 * h);
        assert!((d - s.at(t)[1]).abs() < 1e-8 && (dd - s.at(t)[2]).abs() < 1e-6);
    }

    #[test]
    fn spline_rejects_bad_samples() {
        assert!(CubicSpline::new(&[[0.0, 1.0]]).is_none());
        assert!(CubicSpline::new(&[[0.0, 1.0], [0.0, 2.0]]).is_none());
        assert!(CubicSpline::new(&[[0.0, 1.0], [1.0, f64::NAN]]).is_none());
        // Times spanning ±1e308: each is finite, their spacing is not, and q(0) was NaN.
        assert!(CubicSpline::new(&[[-1e308, 0.0], [1e308, 1.0]]).is_none());
        // Values near the limit whose curve overflows between samples.
        assert!(CubicSpline::new(&[[0.0, 1.7e308], [1.0, 1.7e308], [2.0, 1.7e308]]).is_some());
        assert!(CubicSpline::new(&[[0.0, -1e308], [1.0, 0.0], [2.0, 1e308]]).is_some());
    }

    #[test]
    fn sine_derivatives() {
        let m = Motion::Sine {
            offset: 0.1,
            amplitude: 0.3,
            frequency: 0.7,
            phase: 0.2,
        };
        let (t, h) = (0.4, 1e-6);
        let d = (m.at(t + h)[0] - m.at(t - h)[0]) / (2.0 * h);
        let dd = (m.at(t + h)[1] - m.at(t - h)[1]) / (2.0 * h);
        assert!((d - m.at(t)[1]).abs() < 1e-8 && (dd - m.at(t)[2]).abs() < 1e-6);
    }
}
