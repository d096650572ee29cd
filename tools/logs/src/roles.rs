//! Signal roles and their units: what a log column means and how it converts to SI.

use crate::LogsError;

/// What a log column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Role {
    /// Time.
    Time,
    /// Joint position s.
    S,
    /// Joint velocity ṡ.
    Sdot,
    /// Joint acceleration s̈.
    Sddot,
    /// Motor position θ (motor side).
    Theta,
    /// Motor velocity ω (motor side).
    Omega,
    /// Motor current.
    Current,
    /// Joint torque sensor (link side).
    TauJoint,
    /// Commanded or motor-side torque reflected to the joint.
    TauMotor,
    /// Friction torque (a given label).
    TauF,
    /// Temperature.
    Temperature,
}

/// A unit of a role, with its factor to the SI unit the pipeline uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unit {
    /// Canonical spelling (`deg`, `mA`, …).
    pub name: &'static str,
    /// Multiply a value in this unit by this to get the role's SI unit.
    pub factor: f64,
}

const fn u(name: &'static str, factor: f64) -> Unit {
    Unit { name, factor }
}

const DEG: f64 = std::f64::consts::PI / 180.0;
const TIME: &[Unit] = &[u("s", 1.0), u("ms", 1e-3), u("us", 1e-6), u("µs", 1e-6)];
const ANGLE: &[Unit] = &[u("rad", 1.0), u("deg", DEG)];
const VEL: &[Unit] = &[
    u("rad/s", 1.0),
    u("deg/s", DEG),
    u("rpm", 2.0 * std::f64::consts::PI / 60.0),
];
const ACC: &[Unit] = &[u("rad/s^2", 1.0), u("deg/s^2", DEG)];
const CURRENT: &[Unit] = &[u("A", 1.0), u("mA", 1e-3)];
const TORQUE: &[Unit] = &[u("Nm", 1.0), u("mNm", 1e-3)];
const TEMP: &[Unit] = &[u("C", 1.0)];

impl Role {
    /// Every role, in canonical order.
    pub const ALL: [Role; 11] = [
        Role::Time,
        Role::S,
        Role::Sdot,
        Role::Sddot,
        Role::Theta,
        Role::Omega,
        Role::Current,
        Role::TauJoint,
        Role::TauMotor,
        Role::TauF,
        Role::Temperature,
    ];

    /// The role's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Role::Time => "time",
            Role::S => "s",
            Role::Sdot => "sdot",
            Role::Sddot => "sddot",
            Role::Theta => "theta",
            Role::Omega => "omega",
            Role::Current => "current",
            Role::TauJoint => "tau_joint",
            Role::TauMotor => "tau_motor",
            Role::TauF => "tau_f",
            Role::Temperature => "temperature",
        }
    }

    /// Parses a role name (`tau-f` is accepted for `tau_f`).
    pub fn parse(text: &str) -> Result<Role, LogsError> {
        let t = text.trim().replace('-', "_");
        Role::ALL
            .into_iter()
            .find(|r| r.name() == t)
            .ok_or_else(|| LogsError::UnknownRole {
                value: text.to_string(),
                accepted: Role::ALL.map(Role::name).join(", "),
            })
    }

    /// The units this role accepts; the first is the SI unit the pipeline uses.
    pub fn units(self) -> &'static [Unit] {
        match self {
            Role::Time => TIME,
            Role::S | Role::Theta => ANGLE,
            Role::Sdot | Role::Omega => VEL,
            Role::Sddot => ACC,
            Role::Current => CURRENT,
            Role::TauJoint | Role::TauMotor | Role::TauF => TORQUE,
            Role::Temperature => TEMP,
        }
    }

    /// The SI unit.
    pub fn si(self) -> Unit {
        self.units()[0]
    }

    /// Parses a unit for this role (`degC`/`°C` for `C`, `rad/s2` for `rad/s^2`, `N.m` for `Nm`).
    pub fn parse_unit(self, text: &str) -> Result<Unit, LogsError> {
        let t = text.trim();
        let norm = match t {
            "degC" | "°C" | "celsius" => "C",
            "rad/s2" | "rad/s²" => "rad/s^2",
            "deg/s2" | "deg/s²" => "deg/s^2",
            "N.m" | "N*m" | "N m" => "Nm",
            "mN.m" | "mN*m" => "mNm",
            "sec" => "s",
            other => other,
        };
        self.units()
            .iter()
            .copied()
            .find(|u| u.name == norm)
            .ok_or_else(|| LogsError::UnknownUnit {
                role: self,
                value: t.to_string(),
                accepted: self
                    .units()
                    .iter()
                    .map(|u| u.name)
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_and_units_parse_and_reject() {
        assert_eq!(Role::parse("tau-f").unwrap(), Role::TauF);
        let e = Role::parse("speed").unwrap_err().to_string();
        assert!(e.contains("speed") && e.contains("tau_joint"), "{e}");
        assert_eq!(Role::S.parse_unit("deg").unwrap().factor, DEG);
        assert!(
            (Role::Omega.parse_unit("rpm").unwrap().factor - 0.10471975511965977).abs() < 1e-15
        );
        assert_eq!(Role::Time.parse_unit("µs").unwrap().factor, 1e-6);
        let e = Role::Current.parse_unit("deg").unwrap_err().to_string();
        assert!(e.contains("A, mA"), "{e}");
    }
}
