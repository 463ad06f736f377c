//! Plant models implementing [`crate::TransitionModel`] and [`crate::ObservationModel`].

pub mod intake;
pub mod linear;
pub mod throttle;
pub mod throttle_identification;
