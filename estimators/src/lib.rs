//! fdd-estimators: the filters and plant models that fdd's monitors use as residual generators.
//!
//! Pure math: no I/O, no clock, and no heap allocation in any Kalman-type predict or update
//! (fixed-size `nalgebra` types throughout). Every update returns an [`Innovation`] for the
//! detectors; every failure is a [`FilterError`] value and leaves the filter's estimate as it was.
//!
//! - [`model`]: the [`TransitionModel`] / [`ObservationModel`] traits a plant implements.
//! - [`ekf::Ekf`], [`ukf::Ukf`] with the [`sigma_points`] sets AHSM, ARM, AGM and scaled.
//! - [`fusion`]: the decentralized pair of local EKFs with the naive master fusion, and the
//!   federated filter (information-sharing factors, fusion-reset) that equals the centralized EKF.
//! - [`particle::ParticleFilter`]: a bootstrap reference estimator (allocates at construction).
//! - [`models`]: the electronic throttle and a linear model.
//! - [`dare`]: the discrete algebraic Riccati equation (structure-preserving doubling) and the
//!   stationary Kalman gains built on it, for observers with constant gains.

pub mod correction;
pub mod dare;
pub mod ekf;
pub mod error;
pub mod fusion;
pub mod innovation;
pub mod linalg;
pub mod model;
pub mod models;
pub mod noise_level;
pub mod param;
pub mod particle;
pub mod reacquire;
pub mod sigma_points;
pub mod ukf;

pub use ekf::Ekf;
pub use error::{ConfigError, FilterError};
pub use fusion::{DecentralizedPair, FederatedFilter, FusedStep, FusionNoise};
pub use innovation::Innovation;
pub use model::{numerical_jacobian, ObservationModel, TransitionModel};
pub use noise_level::NoiseLevel;
pub use param::{ParamError, Range};
pub use sigma_points::{SigmaKind, SigmaPoints};
pub use ukf::Ukf;
