//! ABC model (Löw et al. 2012).

#[derive(Clone, Debug, PartialEq)]
pub struct AbcParams {
    pub kd: [f64; 3],
    pub a: [f64; 3],
    pub b: f64,
    pub c: f64,
    pub ior: f64,
}
