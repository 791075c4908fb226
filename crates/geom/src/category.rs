//! The object categories irmirror knows, and the physical facts shared about them.
//!
//! One type from the capture file to the command line: `capture.toml`'s `category`, scene files,
//! the object priors, stage 1's families, the benchmark's rows and the CLI's `--category` all
//! parse into [`Category`] once and pass the enum on.

use serde::{Deserialize, Serialize};

/// Typical passenger-car length, metres (4.0–5.0 m; the centre of stage 1's car size prior and
/// the simulator's car length).
pub const CAR_LENGTH_M: f64 = 4.5;

/// An object category.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Category {
    /// Bowls: thin shells of revolution.
    Bowl,
    /// Mugs and cups: a cup with a handle.
    #[serde(alias = "cup")]
    #[cfg_attr(feature = "clap", value(alias = "cup"))]
    Mug,
    /// Cars: sedans, hatchbacks and SUVs.
    Car,
    /// Spheres and balls (no learned prior; used by tests and hand-made scenes).
    #[serde(alias = "ball")]
    #[cfg_attr(feature = "clap", value(alias = "ball"))]
    Sphere,
}

impl Category {
    /// Every category.
    pub const ALL: [Category; 4] = [
        Category::Bowl,
        Category::Mug,
        Category::Car,
        Category::Sphere,
    ];

    /// The categories with a learned (DeepSDF) prior.
    pub const LEARNED: [Category; 3] = [Category::Bowl, Category::Mug, Category::Car];

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Category::Bowl => "bowl",
            Category::Mug => "mug",
            Category::Car => "car",
            Category::Sphere => "sphere",
        }
    }

    /// Whether a learned prior exists for it.
    pub fn has_learned_prior(self) -> bool {
        Self::LEARNED.contains(&self)
    }

    /// A typical largest dimension, metres (soup and cereal bowls 12–25 cm across; mugs 8–12
    /// cm tall, 11–13 cm with the handle; cars [`CAR_LENGTH_M`]; balls 7–25 cm): for telling a
    /// file in millimetres or inches from one in metres.
    pub fn typical_size_m(self) -> f64 {
        match self {
            Category::Bowl => 0.18,
            Category::Mug => 0.12,
            Category::Car => CAR_LENGTH_M,
            Category::Sphere => 0.15,
        }
    }
}

impl std::fmt::Display for Category {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a category.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown object category `{0}` (known: bowl, mug (or cup), car, sphere (or ball))")]
pub struct UnknownCategory(pub String);

impl std::str::FromStr for Category {
    type Err = UnknownCategory;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "bowl" => Ok(Category::Bowl),
            "mug" | "cup" => Ok(Category::Mug),
            "car" => Ok(Category::Car),
            "sphere" | "ball" => Ok(Category::Sphere),
            other => Err(UnknownCategory(other.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_serde_agrees() {
        for c in Category::ALL {
            assert_eq!(c.name().parse::<Category>(), Ok(c));
            assert_eq!(serde_json::to_string(&c).unwrap(), format!("\"{c}\""));
            assert_eq!(
                serde_json::from_str::<Category>(&format!("\"{c}\"")).unwrap(),
                c
            );
        }
        assert_eq!("cup".parse::<Category>(), Ok(Category::Mug));
        assert_eq!(
            serde_json::from_str::<Category>("\"ball\"").unwrap(),
            Category::Sphere
        );
        assert!("chair".parse::<Category>().is_err());
        assert!(serde_json::from_str::<Category>("\"chair\"").is_err());
        assert!(!Category::Sphere.has_learned_prior() && Category::Car.has_learned_prior());
    }
}
