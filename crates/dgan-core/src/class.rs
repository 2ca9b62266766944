//! Agent classes and their default sizes.

use crate::error::{DganError, Result};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// The classes of traffic the engine knows (the paper's three categories).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AgentClass {
    /// Cars, buses, trucks, carts.
    Vehicle,
    /// Bicycles, motorcycles, skaters.
    Cyclist,
    /// People on foot.
    Pedestrian,
}

impl AgentClass {
    /// All classes, in their canonical order (the integer codes 0, 1, 2).
    pub const ALL: [AgentClass; 3] = [AgentClass::Vehicle, AgentClass::Cyclist, AgentClass::Pedestrian];

    /// The lowercase name used in model metadata and the Python API.
    pub fn name(self) -> &'static str {
        match self {
            AgentClass::Vehicle => "vehicle",
            AgentClass::Cyclist => "cyclist",
            AgentClass::Pedestrian => "pedestrian",
        }
    }

    /// The canonical integer code (0 vehicle, 1 cyclist, 2 pedestrian).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The class of a canonical integer code.
    pub fn from_code(code: i64) -> Result<Self> {
        usize::try_from(code).ok().and_then(|i| Self::ALL.get(i).copied()).ok_or_else(|| {
            DganError::UnknownClass(format!(
                "class code {code}; known codes are 0 (vehicle), 1 (cyclist), 2 (pedestrian)"
            ))
        })
    }

    /// Default length in metres, used when a frame gives none.
    pub fn default_length_m(self) -> f64 {
        match self {
            AgentClass::Vehicle => 4.5,
            AgentClass::Cyclist => 1.8,
            AgentClass::Pedestrian => 0.5,
        }
    }

    /// Default width in metres, used when a frame gives none.
    pub fn default_width_m(self) -> f64 {
        match self {
            AgentClass::Vehicle => 1.9,
            AgentClass::Cyclist => 0.7,
            AgentClass::Pedestrian => 0.5,
        }
    }
}

impl fmt::Display for AgentClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for AgentClass {
    type Err = DganError;

    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "vehicle" => Ok(AgentClass::Vehicle),
            "cyclist" => Ok(AgentClass::Cyclist),
            "pedestrian" => Ok(AgentClass::Pedestrian),
            _ => Err(DganError::UnknownClass(format!(
                "{s:?}; known classes are \"vehicle\", \"cyclist\", \"pedestrian\""
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_codes_round_trip() {
        for c in AgentClass::ALL {
            assert_eq!(c.name().parse::<AgentClass>().unwrap(), c);
            assert_eq!(AgentClass::from_code(i64::from(c.code())).unwrap(), c);
        }
        assert_eq!("  Pedestrian ".parse::<AgentClass>().unwrap(), AgentClass::Pedestrian);
    }

    #[test]
    fn unknown_classes_are_errors() {
        assert!(matches!("truck".parse::<AgentClass>(), Err(DganError::UnknownClass(_))));
        assert!(matches!(AgentClass::from_code(3), Err(DganError::UnknownClass(_))));
        assert!(matches!(AgentClass::from_code(-1), Err(DganError::UnknownClass(_))));
    }
}
