//! Shifted gamma distribution model (Bagher et al. 2012).

#[derive(Clone, Debug, PartialEq)]
pub struct SgdParams {
    pub rho_d: [f64; 3],
    pub rho_s: [f64; 3],
    pub alpha: [f64; 3],
    pub p: [f64; 3],
    pub f0: [f64; 3],
    pub f1: [f64; 3],
    pub kap: [f64; 3],
    pub lambda: [f64; 3],
    pub c: [f64; 3],
    pub k: [f64; 3],
    pub theta0: [f64; 3],
}
