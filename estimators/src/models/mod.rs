//! Plant models implementing [`crate::TransitionModel`] and [`crate::ObservationModel`].

pub mod linear;
pub mod throttle;
