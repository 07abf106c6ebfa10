//! RGL material database measurements (`.bsdf`, Dupuy & Jakob 2018, "An Adaptive
//! Parameterization for Efficient Material Acquisition and Rendering"), read and evaluated as
//! Mitsuba 3's `measured` BSDF does.
//!
//! * [`tensor`] – the tensor file container (`TensorFile`).
//! * [`warp`]   – the `Marginal2D` interpolant and inverse warp the tables are read through.
//! * [`eval`]   – the BSDF evaluation (`measured.cpp`'s `eval`), in RGB and per wavelength.
//!
//! Two kinds of files: RGB (`*_rgb.bsdf`, a field `rgb` of three channels), evaluated as in
//! Mitsuba's RGB variants, and spectral (`*_spec.bsdf`, fields `wavelengths` in nm and `spectra`
//! with one channel per wavelength), evaluated per wavelength as in its spectral variants and,
//! for everything that works in RGB (training, `Brdf`), through their linear sRGB projection
//! under D65 ([`crate::spectrum`], docs/design.md section 9). As in `measured.cpp`, a file with
//! a `wavelengths` field is spectral.

pub mod eval;
pub mod tensor;
pub mod warp;

use crate::error::{NbrdfError, Result};
use crate::spectrum::SrgbProjection;
use std::path::{Path, PathBuf};
use tensor::TensorFile;
use warp::Marginal2D;

/// The azimuthal reduction applied to isotropic measurements. Mitsuba 3.9's `measured` leaves
/// `m_reduction` unset for them, and its builds behave as if it were 2: both directions are
/// rotated by pi when the view's y is non-negative. For an isotropic material that is a symmetry,
/// except at the half vector `m = n` exactly (mirror configurations), where `phi_m` is taken as 0
/// and the rotation changes `phi_m - phi_i`: the tables' `theta_m = 0` column is not constant in
/// `phi`, so reproducing Mitsuba there needs the same rotation (`tests/test_rgl_reader.py`
/// evaluates exact mirror pairs).
const ISOTROPIC_REDUCTION: i32 = 2;

/// A loaded RGL measurement, ready to evaluate (the interpolants are built at load).
#[derive(Clone, Debug)]
pub struct RglMeasurement {
    path: PathBuf,
    description: String,
    theta_i: Vec<f32>,
    phi_i: Vec<f32>,
    /// The microfacet normal distribution over `(u(theta_m), u(phi_m))`, unnormalised.
    ndf: Marginal2D,
    /// The projected microfacet area over `(u(theta_i), u(phi_i))`, unnormalised.
    sigma: Marginal2D,
    /// The visible normal distribution per incident direction, the adaptive parameterisation
    /// the reflectance tables are stored in.
    vndf: Marginal2D,
    /// Linear sRGB reflectance per incident direction and channel, over the VNDF's sample
    /// space: the file's `rgb`, or the sRGB projection of its `spectra`.
    rgb: Marginal2D,
    /// A spectral file's reflectance per wavelength.
    spectra: Option<Spectra>,
    /// Whether the stored values are divided by the parameterisation's Jacobian (then multiplied
    /// by `D(m) / (4 sigma(wi))` at evaluation).
    jacobian: bool,
    isotropic: bool,
    /// Anisotropic files measured over a half (2) or a quarter (4) of the azimuths: the
    /// directions are mirrored into the measured range.
    reduction: i32,
}

/// A spectral measurement's tables: reflectance per incident direction and wavelength.
#[derive(Clone, Debug)]
pub struct Spectra {
    /// Strictly increasing, in nm.
    wavelengths: Vec<f32>,
    /// Over the VNDF's sample space, with the parameters `(phi_i, theta_i, wavelength)`.
    table: Marginal2D,
}

impl Spectra {
    pub fn wavelengths(&self) -> &[f32] {
        &self.wavelengths
    }
}

/// Why the evaluation could leave the float32 range it is computed in (Mitsuba's RGB variants
/// and [`RglMeasurement::eval_cos_f32`]), or `None`. Interpolation never leaves the range of
/// the values it blends, so `|f cos| <= max |rgb| * max ndf / (4 min sigma)` (the last factor
/// only with the Jacobian flag); beyond `f32::MAX` the product would be infinite, or NaN where a
/// zero reflectance meets an infinite scale, so both the bound and the scale must stay below.
fn float32_range_problem(rgb: &[f32], jacobian: Option<(&[f32], &[f32])>) -> Option<String> {
    let largest = |values: &[f32]| values.iter().fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
    let rgb_max = largest(rgb);
    let scale = match jacobian {
        Some((ndf, sigma)) => {
            let sigma_min = sigma
                .iter()
                .fold(f64::INFINITY, |m, v| m.min(f64::from(*v)));
            largest(ndf) / (4.0 * sigma_min)
        }
        None => 1.0,
    };
    // With a margin for the rounding of the interpolation weights.
    let scale = scale * (1.0 + 1e-5);
    let bound = rgb_max * scale;
    // The scale is a float32 product of its own (an infinite one turns a zero reflectance NaN).
    let limit = f64::from(f32::MAX);
    (!(scale <= limit && bound <= limit)).then(|| {
        format!(
            "values up to {rgb_max:e} times the Jacobian's largest ndf / (4 sigma) = {scale:e} \
             can reach {bound:e}, beyond the float32 range (3.4e38) the measurement is \
             evaluated in"
        )
    })
}

/// The wavelengths of a spectral file (`None` for an RGB one), checked to be usable: at least
/// two, strictly increasing, overlapping the visible range. A file with neither `rgb` nor
/// `wavelengths` is not a measurement.
fn read_wavelengths(file: &TensorFile) -> Result<Option<(Vec<f32>, SrgbProjection)>> {
    if !file.has_field("wavelengths") {
        if file.has_field("rgb") {
            return Ok(None);
        }
        return Err(file.error(
            "rgb",
            "missing, and no \"wavelengths\" either (not an RGL measurement?)".into(),
        ));
    }
    let (_, wavelengths) = file.f32_array("wavelengths", 1)?;
    let as_f64: Vec<f64> = wavelengths.iter().map(|&l| f64::from(l)).collect();
    let projection = SrgbProjection::new(&as_f64).map_err(|e| match e {
        NbrdfError::InvalidArgument(message) => file.error("wavelengths", message),
        other => other,
    })?;
    Ok(Some((wavelengths, projection)))
}

/// `theta_i` and `phi_i`, each non-empty and strictly increasing.
fn read_angles(file: &TensorFile) -> Result<(Vec<f32>, Vec<f32>)> {
    let (_, theta_i) = file.f32_array("theta_i", 1)?;
    let (_, phi_i) = file.f32_array("phi_i", 1)?;
    for (name, values) in [("theta_i", &theta_i), ("phi_i", &phi_i)] {
        if values.is_empty() {
            return Err(file.error(name, "is empty".into()));
        }
        if !values.windows(2).all(|w| w[0] < w[1]) {
            return Err(file.error(
                name,
                format!("angles {values:?} are not strictly increasing"),
            ));
        }
    }
    Ok((theta_i, phi_i))
}

/// The tensor fields of a measurement as read, with their shapes, before validation.
struct RawFields {
    ndf: (Vec<usize>, Vec<f32>),
    sigma: (Vec<usize>, Vec<f32>),
    vndf: (Vec<usize>, Vec<f32>),
    luminance_shape: Vec<usize>,
    /// `rgb`, or `spectra` for a spectral file: `[phi_i, theta_i, channel, n, n]`.
    rgb: (Vec<usize>, Vec<f32>),
    jacobian: (Vec<usize>, Vec<u8>),
    /// What the third axis of `rgb` is: the channels 0, 1, 2, or the file's wavelengths.
    channels: Vec<f32>,
    /// `"rgb"` or `"spectra"`, for errors.
    values_name: &'static str,
}

impl RawFields {
    fn read(file: &TensorFile, wavelengths: Option<&[f32]>) -> Result<Self> {
        let (values_name, channels) = match wavelengths {
            Some(w) => ("spectra", w.to_vec()),
            None => ("rgb", vec![0.0, 1.0, 2.0]),
        };
        Ok(RawFields {
            ndf: file.f32_array("ndf", 2)?,
            sigma: file.f32_array("sigma", 2)?,
            vndf: file.f32_array("vndf", 4)?,
            luminance_shape: file.f32_array("luminance", 4)?.0,
            rgb: file.f32_array(values_name, 5)?,
            jacobian: file.u8_array("jacobian", 1)?,
            channels,
            values_name,
        })
    }

    /// Checks the shapes against each other and the `n_phi` x `n_theta` incident angles.
    fn check_shapes(&self, file: &TensorFile, n_phi: usize, n_theta: usize) -> Result<()> {
        let expect = |name: &str, shape: &[usize], ok: bool, expected: String| {
            if ok {
                Ok(())
            } else {
                Err(file.error(name, format!("shape {shape:?}, expected {expected}")))
            }
        };
        let grid_ok = |h: usize, w: usize| h >= 2 && w >= 2;
        let (ndf, sigma, vndf, rgb) = (&self.ndf.0, &self.sigma.0, &self.vndf.0, &self.rgb.0);
        expect(
            "ndf",
            ndf,
            grid_ok(ndf[0], ndf[1]),
            "at least [2, 2]".into(),
        )?;
        expect(
            "sigma",
            sigma,
            grid_ok(sigma[0], sigma[1]),
            "at least [2, 2]".into(),
        )?;
        expect(
            "vndf",
            vndf,
            vndf[..2] == [n_phi, n_theta] && grid_ok(vndf[2], vndf[3]),
            format!("[{n_phi} (phi_i), {n_theta} (theta_i), >= 2, >= 2]"),
        )?;
        let (res_y, res_x) = (rgb[3], rgb[4]);
        let n_channels = self.channels.len();
        let channels = match self.values_name {
            "rgb" => "3".to_string(),
            _ => format!("{n_channels} (wavelengths)"),
        };
        expect(
            self.values_name,
            rgb,
            rgb[..3] == [n_phi, n_theta, n_channels] && res_y == res_x && res_x >= 2,
            format!("[{n_phi} (phi_i), {n_theta} (theta_i), {channels}, n, n] with n >= 2"),
        )?;
        expect(
            "luminance",
            &self.luminance_shape,
            self.luminance_shape[..] == [n_phi, n_theta, res_y, res_x],
            format!(
                "[{n_phi}, {n_theta}, {res_y}, {res_x}] (as phi_i, theta_i and {})",
                self.values_name
            ),
        )?;
        let jacobian = &self.jacobian.0;
        expect("jacobian", jacobian, jacobian[..] == [1], "[1]".into())
    }

    /// Checks the values (densities non-negative, areas positive, RGB within float32 once
    /// evaluated) and returns the Jacobian flag.
    fn check_values(&self, file: &TensorFile) -> Result<bool> {
        let fail = |name: &str, message: String| Err(file.error(name, message));
        let jacobian = match self.jacobian.1[0] {
            0 => false,
            1 => true,
            other => return fail("jacobian", format!("flag is {other}, expected 0 or 1")),
        };
        if let Some(v) = self.vndf.1.iter().find(|v| **v < 0.0) {
            return fail("vndf", format!("holds the negative density {v}"));
        }
        let (ndf, sigma) = (&self.ndf.1, &self.sigma.1);
        if jacobian {
            if let Some(v) = ndf.iter().find(|v| **v < 0.0) {
                return fail("ndf", format!("holds the negative density {v}"));
            }
            // Subnormal areas interpolate to 0 (and the Jacobian to infinity or NaN).
            if let Some(v) = sigma.iter().find(|v| **v < f32::MIN_POSITIVE) {
                return fail(
                    "sigma",
                    format!(
                        "holds {v}; the projected area must be positive and at least {:e} \
                         (float32's smallest normal number)",
                        f32::MIN_POSITIVE
                    ),
                );
            }
        }
        if let Some(problem) = float32_range_problem(&self.rgb.1, jacobian.then_some((ndf, sigma)))
        {
            return fail(self.values_name, problem);
        }
        Ok(jacobian)
    }

    /// The sRGB projection of a spectral file's `spectra` (see [`crate::spectrum`]): shape
    /// `[phi_i, theta_i, 3, n, n]` and values, checked to stay within float32 once evaluated.
    fn projected(
        &self,
        file: &TensorFile,
        projection: &SrgbProjection,
        jacobian: bool,
    ) -> Result<(Vec<usize>, Vec<f32>)> {
        let (shape, spectra) = (&self.rgb.0, &self.rgb.1);
        let (n_channels, cells) = (shape[2], shape[3] * shape[4]);
        let mut rgb = Vec::with_capacity(spectra.len() / n_channels * 3);
        let mut samples = vec![0.0f32; n_channels];
        for block in spectra.chunks_exact(n_channels * cells) {
            let start = rgb.len();
            rgb.resize(start + 3 * cells, 0.0);
            for cell in 0..cells {
                for (k, sample) in samples.iter_mut().enumerate() {
                    *sample = block[k * cells + cell];
                }
                for (c, value) in projection.project(&samples).into_iter().enumerate() {
                    rgb[start + c * cells + cell] = value as f32;
                }
            }
        }
        let scale = jacobian.then_some((self.ndf.1.as_slice(), self.sigma.1.as_slice()));
        if let Some(problem) = float32_range_problem(&rgb, scale) {
            return Err(file.error("spectra", format!("projected to sRGB: {problem}")));
        }
        let mut rgb_shape = shape.clone();
        rgb_shape[2] = 3;
        Ok((rgb_shape, rgb))
    }

    /// The `ndf`, `sigma`, `vndf` and `rgb` (or `spectra`) interpolants, with the arguments
    /// measured.cpp constructs its Marginal2D tables with.
    fn tables(self, file: &TensorFile, phi_i: &[f32], theta_i: &[f32]) -> Result<[Marginal2D; 4]> {
        let structure = |name: &str, e: NbrdfError| match e {
            NbrdfError::InvalidArgument(message) => file.error(name, message),
            other => other,
        };
        let (ndf_shape, ndf) = self.ndf;
        let (sigma_shape, sigma) = self.sigma;
        let (vndf_shape, vndf) = self.vndf;
        let angles = vec![phi_i.to_vec(), theta_i.to_vec()];
        let ndf = Marginal2D::new(&ndf, ndf_shape[1], ndf_shape[0], vec![], false, false)
            .map_err(|e| structure("ndf", e))?;
        let sigma = Marginal2D::new(&sigma, sigma_shape[1], sigma_shape[0], vec![], false, false)
            .map_err(|e| structure("sigma", e))?;
        let vndf = Marginal2D::new(&vndf, vndf_shape[3], vndf_shape[2], angles, true, true)
            .map_err(|e| structure("vndf", e))?;
        let (shape, values) = &self.rgb;
        let rgb = reflectance_table(values, shape, [phi_i, theta_i, &self.channels])
            .map_err(|e| structure(self.values_name, e))?;
        Ok([ndf, sigma, vndf, rgb])
    }
}

/// The reflectance interpolant over the VNDF's sample space, `shape` `[phi_i, theta_i,
/// channels, n, n]`, interpolated in the incident angles and the channel (RGB or wavelength).
fn reflectance_table(values: &[f32], shape: &[usize], params: [&[f32]; 3]) -> Result<Marginal2D> {
    let params = params.iter().map(|p| p.to_vec()).collect();
    Marginal2D::new(values, shape[4], shape[3], params, false, false)
}

impl RglMeasurement {
    /// Reads and validates the RGL measurement at `path`.
    pub fn load(path: impl AsRef<Path>) -> Result<RglMeasurement> {
        let file = TensorFile::read(path)?;
        RglMeasurement::from_tensor_file(&file)
    }

    /// Builds the measurement from a parsed tensor file, validating every field Mitsuba's
    /// `measured` plugin reads (presence, dtype, shape, finite values) and the preconditions of
    /// its interpolants that Mitsuba leaves unchecked (sorted angles, positive normalisations).
    pub fn from_tensor_file(file: &TensorFile) -> Result<RglMeasurement> {
        let spectral = read_wavelengths(file)?;
        let (_, description) = file.u8_array("description", 1)?;
        let description = String::from_utf8_lossy(&description).into_owned();
        let (theta_i, phi_i) = read_angles(file)?;
        let fields = RawFields::read(file, spectral.as_ref().map(|(w, _)| w.as_slice()))?;
        fields.check_shapes(file, phi_i.len(), theta_i.len())?;
        let jacobian = fields.check_values(file)?;
        let projected = match &spectral {
            Some((_, projection)) => Some(fields.projected(file, projection, jacobian)?),
            None => None,
        };
        let isotropic = phi_i.len() <= 2;
        let reduction = if isotropic {
            ISOTROPIC_REDUCTION
        } else {
            let span = phi_i[phi_i.len() - 1] - phi_i[0];
            (2.0 * std::f32::consts::PI / span).round_ties_even() as i32
        };
        let [ndf, sigma, vndf, values] = fields.tables(file, &phi_i, &theta_i)?;
        let (rgb, spectra) = match (spectral, projected) {
            (Some((wavelengths, _)), Some((shape, rgb))) => {
                let channels: &[f32] = &[0.0, 1.0, 2.0];
                let rgb = reflectance_table(&rgb, &shape, [&phi_i, &theta_i, channels])
                    .map_err(|e| file.error("spectra", e.to_string()))?;
                let table = values;
                (rgb, Some(Spectra { wavelengths, table }))
            }
            _ => (values, None),
        };
        Ok(RglMeasurement {
            path: file.path().to_path_buf(),
            description,
            theta_i,
            phi_i,
            ndf,
            sigma,
            vndf,
            rgb,
            spectra,
            jacobian,
            isotropic,
            reduction,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's description of the material (e.g. "White A4 paper (160 gsm)").
    pub fn description(&self) -> &str {
        &self.description
    }

    /// The spectral tables of a spectral file (`*_spec.bsdf`), `None` for an RGB one.
    pub fn spectra(&self) -> Option<&Spectra> {
        self.spectra.as_ref()
    }

    pub fn is_isotropic(&self) -> bool {
        self.isotropic
    }

    /// The incident elevations the measurement was taken at (radians).
    pub fn theta_i(&self) -> &[f32] {
        &self.theta_i
    }

    /// The incident azimuths the measurement was taken at (one value for isotropic materials).
    pub fn phi_i(&self) -> &[f32] {
        &self.phi_i
    }
}
