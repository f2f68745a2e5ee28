//! What a friction measurement measures (docs/spec/recording-format.md,
//! `/measurement/friction`): the model predicts each, a generic term on
//! `measurement` may be scoped to one.

#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// Friction coefficient of a wheel–rail contact.
    Mu,
    /// Coefficient of adhesion T/N of a wheel–rail contact.
    Adhesion,
    /// Hand tribometer on the rail surface alone.
    RailMu,
}

impl Quantity {
    pub fn as_str(self) -> &'static str {
        match self {
            Quantity::Mu => "mu",
            Quantity::Adhesion => "adhesion",
            Quantity::RailMu => "rail_mu",
        }
    }
}
