//! Plant models implementing [`crate::TransitionModel`] and [`crate::ObservationModel`].
//! [`turbo`]: the 13-state mean value model of a turbocharged SI engine's air path.
//! [`wheel`]: the quarter car of the slip-control tutorial and its 5-state EKF.

pub mod intake;
pub mod linear;
pub mod throttle;
pub mod throttle_identification;
pub mod turbo;
pub mod wheel;
