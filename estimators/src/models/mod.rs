//! Plant models implementing [`crate::TransitionModel`] and [`crate::ObservationModel`].
//! [`turbo`]: the 13-state mean value model of a turbocharged SI engine's air path.

pub mod intake;
pub mod linear;
pub mod throttle;
pub mod throttle_identification;
pub mod turbo;
