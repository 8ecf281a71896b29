//! The integrators' names: one vocabulary for the command line, task files, Python and the
//! library (`vi`, `rk4`, `rk45`), parsed in one place.

use std::fmt;
use std::str::FromStr;

/// An integrator, by the name every front end gives it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Integrator {
    /// `vi`: the midpoint variational integrator (energy-stable, momentum-conserving).
    #[default]
    Vi,
    /// `rk4`: classical fixed-step fourth-order Runge–Kutta.
    Rk4,
    /// `rk45`: Dormand–Prince 5(4), adaptive when simulating (one step of the given length
    /// when linearised).
    Rk45,
}

impl Integrator {
    /// Every integrator, in the order they are listed to users.
    pub const ALL: [Integrator; 3] = [Integrator::Vi, Integrator::Rk4, Integrator::Rk45];

    /// Its name: `vi`, `rk4` or `rk45`.
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Vi => "vi",
            Integrator::Rk4 => "rk4",
            Integrator::Rk45 => "rk45",
        }
    }

    /// A line on what it is, for help texts.
    pub fn summary(self) -> &'static str {
        match self {
            Integrator::Vi => {
                "the midpoint variational integrator (energy-stable, momentum-conserving)"
            }
            Integrator::Rk4 => "classical fixed-step fourth-order Runge–Kutta",
            Integrator::Rk45 => {
                "Dormand–Prince 5(4): adaptive in a run, one step of --dt when linearised"
            }
        }
    }
}

impl FromStr for Integrator {
    type Err = String;

    /// Parses a name; the error is a sentence naming what was given and the choices.
    fn from_str(name: &str) -> Result<Self, String> {
        Integrator::ALL
            .into_iter()
            .find(|i| i.name() == name)
            .ok_or_else(|| format!("integrator `{name}`: use `vi`, `rk4` or `rk45`"))
    }
}

impl fmt::Display for Integrator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_parses_back_and_others_are_refused_with_the_choices() {
        for i in Integrator::ALL {
            assert_eq!(i.name().parse::<Integrator>(), Ok(i));
            assert_eq!(i.to_string(), i.name());
        }
        let e = "RK4".parse::<Integrator>().unwrap_err();
        assert_eq!(e, "integrator `RK4`: use `vi`, `rk4` or `rk45`");
    }
}
