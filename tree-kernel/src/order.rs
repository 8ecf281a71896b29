//! How much of the Lagrangian's derivative tower an evaluation computes.

/// How much of the Lagrangian's derivative tower to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Order {
    /// `L`, `∂L/∂q`, `∂L/∂q̇` (enough for the VI residual, eqs. (23)–(24)).
    First,
    /// Also `M = ∂²L/∂q̇²` and `∂²L/∂q̇∂q` (enough for continuous dynamics, eq. (14)).
    Dynamics,
    /// Also `∂²L/∂q²` (the VI's exact Newton Jacobian, eq. (26)).
    Full,
}
