//! Numbers as messages, summaries and `check` print them: one rule for every value a user
//! reads, so a stiffness of `1e300` or a length of `-1e200` is never three hundred digits.

use std::fmt;

/// Outside this range of magnitudes (and for non-finite values) numbers print in exponent
/// form; inside it, in Rust's shortest round-trip form.
const PLAIN: std::ops::Range<f64> = 1e-6..1e9;

/// A number as given: Rust's shortest form that reads back to the same `f64` (`0.1`,
/// `-9.81`), in exponent form below 10⁻⁶ and from 10⁹ on (`3e-7`, `1e300`).
///
/// ```
/// use tree_model::Given;
/// assert_eq!(Given(-9.81).to_string(), "-9.81");
/// assert_eq!(Given(1e300).to_string(), "1e300");
/// assert_eq!(Given(2.5e-7).to_string(), "2.5e-7");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Given(pub f64);

impl fmt::Display for Given {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0.abs();
        if x == 0.0 {
            // `-0` reads as a sign error to most eyes.
            f.write_str("0")
        } else if x.is_finite() && PLAIN.contains(&x) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

/// A computed number without its rounding noise: rounded to `.1` significant digits, then
/// printed as [`Given`] (`Rounded(0.5624999999999999, 12)` is `0.5625`, `Rounded(17.451901000000003, 12)`
/// is `17.451901`).
///
/// ```
/// use tree_model::Rounded;
/// assert_eq!(Rounded(0.1 + 0.2, 12).to_string(), "0.3");
/// assert_eq!(Rounded(2.5e9 + 1e-3, 12).to_string(), "2.5e9");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rounded(pub f64, pub usize);

impl fmt::Display for Rounded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Rounded(x, digits) = *self;
        let rounded = if x.is_finite() {
            let text = format!("{x:.*e}", digits.saturating_sub(1));
            text.parse().unwrap_or(x)
        } else {
            x
        };
        Given(rounded).fmt(f)
    }
}

#[cfg(test)]
mod tests {
    use super::{Given, Rounded};

    #[test]
    fn numbers_print_short_and_never_as_hundreds_of_digits() {
        let given = |x: f64| Given(x).to_string();
        assert_eq!(given(0.0), "0");
        assert_eq!(given(-0.0), "0");
        assert_eq!(given(12.25), "12.25");
        assert_eq!(given(-1e200), "-1e200");
        assert_eq!(given(1e-7), "1e-7");
        assert_eq!(given(123456789.5), "123456789.5");
        assert_eq!(given(f64::NAN), "NaN");
        assert_eq!(given(f64::INFINITY), "inf");
        let rounded = |x: f64| Rounded(x, 12).to_string();
        assert_eq!(rounded(0.5624999999999999), "0.5625");
        assert_eq!(rounded(17.451901000000003), "17.451901");
        assert_eq!(rounded(1e300), "1e300");
        assert_eq!(rounded(3e-7), "3e-7");
        assert_eq!(rounded(-0.1), "-0.1");
    }
}

/// A count with its noun, plural unless one (a consonant's `y` becomes `ies`):
/// `Counted(1, "input")` is `1 input`, `Counted(2, "entry")` is `2 entries`.
///
/// ```
/// use tree_model::Counted;
/// assert_eq!(Counted(1, "input").to_string(), "1 input");
/// assert_eq!(Counted(0, "variable").to_string(), "0 variables");
/// assert_eq!(Counted(3, "entry").to_string(), "3 entries");
/// assert_eq!(Counted(1, "entry").to_string(), "1 entry");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Counted<'a>(pub usize, pub &'a str);

impl fmt::Display for Counted<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (n, noun) = (self.0, self.1);
        if n == 1 {
            return write!(f, "1 {noun}");
        }
        let consonant_y =
            noun.ends_with('y') && !noun[..noun.len() - 1].ends_with(['a', 'e', 'i', 'o', 'u']);
        match consonant_y {
            true => write!(f, "{n} {}ies", &noun[..noun.len() - 1]),
            false => write!(f, "{n} {noun}s"),
        }
    }
}
