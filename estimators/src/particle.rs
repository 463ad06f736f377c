//! Bootstrap particle filter, used as a reference estimator: with enough particles its posterior
//! mean is close to the best any filter can do on a model, so it bounds what the Kalman-type
//! filters can reach (and shows whether a gap is the filter's fault or the data's).
//!
//! Storage is allocated once at construction; a step allocates nothing.

use nalgebra::{SMatrix, SVector};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

use crate::correction::{check_covariance, check_input, check_measurement};
use crate::error::{ConfigError, FilterError};
use crate::linalg::cholesky;
use crate::model::{ObservationModel, TransitionModel};

/// Sampling-importance-resampling filter with the transition prior as proposal.
#[derive(Debug, Clone)]
pub struct ParticleFilter<T, O, const N: usize, const M: usize, const U: usize> {
    transition: T,
    observation: O,
    particles: Vec<SVector<f64, N>>,
    scratch: Vec<SVector<f64, N>>,
    log_weights: Vec<f64>,
    weights: Vec<f64>,
    noise_factor: SMatrix<f64, N, N>,
    r_chol: SMatrix<f64, M, M>,
    rng: Pcg64Mcg,
}

impl<T, O, const N: usize, const M: usize, const U: usize> ParticleFilter<T, O, N, M, U>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    /// `count` particles drawn from `N(x0, p0)`. Process noise is `G w`, `w ~ N(0, I)`, with
    /// `noise_factor = G` (so `Q = G G'`, which may be singular); measurement noise `N(0, r)`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        transition: T,
        observation: O,
        count: usize,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        noise_factor: SMatrix<f64, N, N>,
        r: SMatrix<f64, M, M>,
        seed: u64,
    ) -> Result<Self, ConfigError> {
        if count < 2 {
            return Err(ConfigError::InvalidParameter {
                name: "particles",
                value: count as f64,
                reason: "need at least 2 particles",
            });
        }
        check_covariance("P0", &p0, true)?;
        check_covariance("R", &r, true)?;
        let p0_chol = cholesky(&p0).map_err(|_| ConfigError::NotPositive {
            name: "P0",
            kind: "definite",
        })?;
        let r_chol = cholesky(&r).map_err(|_| ConfigError::NotPositive {
            name: "R",
            kind: "definite",
        })?;
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let mut particles = Vec::with_capacity(count);
        for _ in 0..count {
            let z = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
            let mut x = x0 + p0_chol * z;
            transition.constrain(&mut x);
            particles.push(x);
        }
        Ok(Self {
            transition,
            observation,
            scratch: particles.clone(),
            particles,
            log_weights: vec![0.0; count],
            weights: vec![1.0 / count as f64; count],
            noise_factor,
            r_chol,
            rng,
        })
    }

    /// Propagates every particle through the noisy transition.
    pub fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError> {
        check_input(u)?;
        for x in self.particles.iter_mut() {
            let z = SVector::<f64, N>::from_fn(|_, _| self.rng.sample(StandardNormal));
            let mut next = self.transition.transition(x, u) + self.noise_factor * z;
            self.transition.constrain(&mut next);
            *x = next;
        }
        Ok(())
    }

    /// Weights particles by the measurement likelihood and resamples (systematic) when the
    /// effective sample size falls below half the particle count.
    pub fn update(&mut self, y: &SVector<f64, M>, u: &SVector<f64, U>) -> Result<(), FilterError> {
        check_input(u)?;
        check_measurement(y, &[true; M])?;
        let mut max_lw = f64::NEG_INFINITY;
        for (k, x) in self.particles.iter().enumerate() {
            let r = y - self.observation.observe(x, u);
            let white = self
                .r_chol
                .solve_lower_triangular(&r)
                .unwrap_or_else(SVector::zeros);
            let lw = self.weights[k].ln() - 0.5 * white.norm_squared();
            self.log_weights[k] = lw;
            max_lw = max_lw.max(lw);
        }
        if !max_lw.is_finite() {
            return Err(FilterError::NonFiniteResult {
                which: "particle weights",
            });
        }
        let mut total = 0.0;
        for (w, lw) in self.weights.iter_mut().zip(&self.log_weights) {
            *w = (lw - max_lw).exp();
            total += *w;
        }
        let mut sum_sq = 0.0;
        for w in self.weights.iter_mut() {
            *w /= total;
            sum_sq += *w * *w;
        }
        let n = self.particles.len();
        if 1.0 / sum_sq < 0.5 * n as f64 {
            self.resample();
        }
        Ok(())
    }

    fn resample(&mut self) {
        let n = self.particles.len();
        let step = 1.0 / n as f64;
        let mut target = self.rng.random::<f64>() * step;
        let mut cumulative = self.weights[0];
        let mut src = 0;
        for dst in 0..n {
            while target > cumulative && src + 1 < n {
                src += 1;
                cumulative += self.weights[src];
            }
            self.scratch[dst] = self.particles[src];
            target += step;
        }
        std::mem::swap(&mut self.particles, &mut self.scratch);
        self.weights.iter_mut().for_each(|w| *w = step);
    }

    /// Weighted posterior mean.
    pub fn mean(&self) -> SVector<f64, N> {
        self.particles
            .iter()
            .zip(&self.weights)
            .fold(SVector::zeros(), |acc, (x, w)| acc + x * *w)
    }
}
