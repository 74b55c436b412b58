//! The one parser of the names that files, the command line and requests
//! use for closed sets of choices (integrators, estimation methods, mass
//! conventions), and the one wording of its refusal: `'x' is not one of a,
//! b, c`.

use std::fmt;

use serde::Deserialize;

/// A closed set of choices, each with one canonical name.
pub trait Named: Copy + 'static {
    /// Every choice, in the order refusals list them.
    const ALL: &'static [Self];
    /// The canonical name (config files, CSV, the wire, the command line).
    fn name(self) -> &'static str;
}

/// `given` names none of `T`'s choices.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{given}' is not one of {choices}")]
pub struct UnknownName {
    /// The name as given.
    pub given: String,
    /// The accepted names, comma-separated.
    pub choices: String,
}

/// `T`'s choices, comma-separated (`explicit_euler, symplectic_euler, …`).
pub fn choices<T: Named>() -> String {
    T::ALL.iter().map(|t| t.name()).collect::<Vec<_>>().join(", ")
}

/// The choice named `name` exactly.
pub fn parse<T: Named>(name: &str) -> Result<T, UnknownName> {
    T::ALL
        .iter()
        .copied()
        .find(|t| t.name() == name)
        .ok_or_else(|| UnknownName {
            given: name.to_string(),
            choices: choices::<T>(),
        })
}

/// [`parse`] for the command line, which also accepts `-` for `_`
/// (`symplectic-euler`).
pub fn parse_arg<T: Named>(name: &str) -> Result<T, UnknownName> {
    parse(&name.replace('-', "_")).map_err(|e| UnknownName {
        given: name.to_string(),
        ..e
    })
}

/// serde `deserialize_with` through [`parse`], so files refuse a name with
/// the same words as the command line and requests.
pub fn deserialize<'de, D: serde::Deserializer<'de>, T: Named>(d: D) -> Result<T, D::Error> {
    let s = String::deserialize(d)?;
    parse(&s).map_err(serde::de::Error::custom)
}

/// Displays a [`Named`] by its name.
pub struct Name<T>(pub T);

impl<T: Named> fmt::Display for Name<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::Method;
    use crate::scene::MassConvention;
    use crate::sim::Integrator;

    fn round_trip<T: Named + PartialEq + fmt::Debug>() {
        for &t in T::ALL {
            assert_eq!(parse::<T>(t.name()), Ok(t));
        }
    }

    #[test]
    fn every_name_parses_back_and_unknown_names_list_the_choices() {
        round_trip::<Integrator>();
        round_trip::<Method>();
        round_trip::<MassConvention>();
        let e = parse::<Integrator>("leapfrog").unwrap_err();
        assert_eq!(
            e.to_string(),
            "'leapfrog' is not one of explicit_euler, symplectic_euler, rk4, implicit_euler, xpbd"
        );
        assert_eq!(parse_arg::<Integrator>("implicit-euler"), Ok(Integrator::ImplicitEuler));
        assert_eq!(parse_arg::<Integrator>("rk-5").unwrap_err().given, "rk-5");
        assert_eq!(
            parse::<Method>("magic").unwrap_err().to_string(),
            "'magic' is not one of same, same_spring, bcd, gkd, lsq, fit, shape, follow, drape"
        );
    }
}
