//! Holding joints still: a reduced model in which chosen variables are constants (as
//! Pinocchio's `buildReducedModel` locks joints). The Panda's fingers, say, which nothing
//! drives, or a humanoid's free base.

use crate::error::ModelError;
use crate::model::{Joint, Mimic, Model, Parameter, SpringKind};

/// A variable to hold, and where (`None`: at its initial value `q0`).
#[derive(Clone, Debug, PartialEq)]
pub struct Lock {
    /// The variable's name.
    pub variable: String,
    /// The value it is held at.
    pub value: Option<f64>,
}

impl Lock {
    /// Reads `NAME` or `NAME=VALUE` (the command line's `--lock`).
    pub fn parse(text: &str) -> Result<Lock, String> {
        let (name, value) = match text.split_once('=') {
            Some((n, v)) => {
                let x = v.trim().parse::<f64>().ok().filter(|x| x.is_finite());
                let x = x.ok_or_else(|| {
                    format!("--lock `{text}`: `{}` is not a finite number", v.trim())
                })?;
                (n.trim(), Some(x))
            }
            None => (text.trim(), None),
        };
        if name.is_empty() {
            return Err(format!("--lock `{text}` names no variable"));
        }
        Ok(Lock {
            variable: name.to_string(),
            value,
        })
    }
}

impl Model {
    /// This model with each variable of `locks` held as a constant: the frame it drives gets
    /// the constant transform, a constraint length it sets becomes that number, a spring on
    /// it (a constant potential) is dropped, and the remaining variables keep their order.
    /// Unknown names, a variable given twice, or locking every variable are errors.
    ///
    /// ```
    /// let model = tree_model::n_link_pendulum(3);
    /// let held = model.locked(&[tree_model::Lock::parse("q2=0.3").unwrap()]).unwrap();
    /// assert_eq!(held.dof(), 2);
    /// assert_eq!(held.frames[2].joint, tree_model::Joint::Constant(0.3));
    /// ```
    pub fn locked(&self, locks: &[Lock]) -> Result<Model, ModelError> {
        let fail = |m: String| ModelError::single(None, m, None);
        let mut value: Vec<Option<f64>> = vec![None; self.dof()];
        for lock in locks {
            let Some(i) = self.variable_index(&lock.variable) else {
                let names: Vec<&str> = self.variables.iter().map(|v| v.name.as_str()).collect();
                return Err(fail(format!(
                    "cannot lock `{}`: the model has no such variable (it has {})",
                    lock.variable,
                    names.join(", ")
                )));
            };
            if value[i].is_some() {
                return Err(fail(format!("`{}` is locked twice", lock.variable)));
            }
            value[i] = Some(lock.value.unwrap_or(self.variables[i].q0));
        }
        if value.iter().all(Option::is_some) {
            return Err(fail(
                "every variable is locked: a model needs at least one left free".into(),
            ));
        }
        // New index of each kept variable.
        let mut index = vec![None; self.dof()];
        let mut kept = 0;
        for (i, v) in value.iter().enumerate() {
            if v.is_none() {
                index[i] = Some(kept);
                kept += 1;
            }
        }
        let mut model = self.clone();
        model.variables = (0..self.dof())
            .filter(|&i| value[i].is_none())
            .map(|i| self.variables[i].clone())
            .collect();
        for f in &mut model.frames {
            f.joint = match f.joint {
                Joint::Variable(i) => match index[i] {
                    Some(j) => Joint::Variable(j),
                    None => Joint::Constant(value[i].unwrap_or(0.0)),
                },
                // A follower of a locked variable is locked with it.
                Joint::Mimic(m) => match index[m.variable] {
                    Some(j) => Joint::Mimic(Mimic { variable: j, ..m }),
                    None => {
                        Joint::Constant(m.multiplier * value[m.variable].unwrap_or(0.0) + m.offset)
                    }
                },
                constant => constant,
            };
        }
        let strings = model.contacts.strings.iter_mut();
        for c in model.constraints.iter_mut().chain(strings) {
            if let crate::model::ConstraintKind::Distance { length } = &mut c.kind {
                if let Parameter::Variable(i) = *length {
                    *length = match index[i] {
                        Some(j) => Parameter::Variable(j),
                        None => Parameter::Constant(value[i].unwrap_or(0.0)),
                    };
                }
            }
        }
        // An input on a locked variable has nothing left to push.
        model.inputs.retain_mut(|u| match index[u.variable] {
            Some(j) => {
                u.variable = j;
                true
            }
            None => false,
        });
        model.springs.retain_mut(|s| match s.kind {
            SpringKind::Variable(i) => match index[i] {
                Some(j) => {
                    s.kind = SpringKind::Variable(j);
                    true
                }
                None => false,
            },
            SpringKind::Frames(_) => true,
        });
        Ok(model)
    }
}
