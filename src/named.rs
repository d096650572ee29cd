//! [`named_enum!`](crate::named_enum): the one list of names of a fieldless option enum, with its
//! `Display` and `FromStr`, so that libraries offer their choices by name without depending on an
//! argument parser (the applications build their parsers from `NAMES` and `FromStr`).

/// Gives a fieldless enum its one list of names: `ALL`, `NAMES`, `name()`, `Display` and
/// `FromStr` (an unknown name is refused with the list of the known ones).
///
/// ```
/// #[derive(Clone, Copy, Debug, PartialEq)]
/// enum Solver { Lm, Adam }
/// frictionless::named_enum!(Solver, "solver", [Lm = "lm", Adam = "adam"]);
///
/// assert_eq!("adam".parse::<Solver>(), Ok(Solver::Adam));
/// assert_eq!(Solver::Lm.to_string(), "lm");
/// assert_eq!(Solver::NAMES, ["lm", "adam"]);
/// assert_eq!(
///     "bfgs".parse::<Solver>().unwrap_err(),
///     "unknown solver `bfgs` (one of: lm, adam)"
/// );
/// ```
#[macro_export]
macro_rules! named_enum {
    ($ty:ident, $what:literal, [$($var:ident = $name:literal),+ $(,)?]) => {
        impl $ty {
            /// Every value, in declaration order.
            pub const ALL: &'static [$ty] = &[$($ty::$var),+];
            /// The name of every value (as options and files write it), in the order of `ALL`.
            pub const NAMES: &'static [&'static str] = &[$($name),+];
            /// The value's name (as options and files write it).
            pub fn name(self) -> &'static str {
                match self {
                    $($ty::$var => $name),+
                }
            }
        }
        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.name())
            }
        }
        impl ::std::str::FromStr for $ty {
            type Err = ::std::string::String;
            fn from_str(s: &str) -> ::std::result::Result<Self, Self::Err> {
                match s {
                    $($name => Ok($ty::$var),)+
                    _ => Err(format!(
                        "unknown {} `{}` (one of: {})",
                        $what,
                        s,
                        Self::NAMES.join(", ")
                    )),
                }
            }
        }
    };
}
