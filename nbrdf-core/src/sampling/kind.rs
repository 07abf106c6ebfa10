//! The names of the sampling strategies: one canonical word each, one stable number each (the C
//! header's `NBRDF_SAMPLING_*` constants), and the older spellings that still parse, with a note
//! saying which word replaces them.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// Which family of [`super::SamplingStrategy`] a strategy belongs to, without its parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u32)]
pub enum SamplingKind {
    Uniform = 0,
    Cosine = 1,
    /// A Blinn-Phong lobe mixed with a cosine lobe.
    Phong = 2,
    /// Two Blinn-Phong lobes mixed with a cosine lobe.
    TwoLobe = 3,
    /// The data-driven half-vector table.
    Tabulated = 4,
    /// An anisotropic Blinn-Phong lobe mixed with a cosine lobe.
    AnisotropicPhong = 5,
}

/// A name that is no strategy's.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown sampling strategy '{name}' (one of {})",
    SamplingKind::canonical_names()
)]
pub struct UnknownSamplingKind {
    pub name: String,
}

/// A number that is no strategy's code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown sampling kind {0} (one of 0 = uniform, 1 = cosine, 2 = phong, 3 = two_lobe, 4 = tabulated, 5 = anisotropic_phong)")]
pub struct UnknownSamplingCode(pub u32);

/// A name parsed leniently: the kind, and a note when the name was an old spelling of it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParsedKind {
    pub kind: SamplingKind,
    /// Set for a deprecated spelling: which one, and the canonical word to use instead.
    pub deprecation: Option<String>,
}

/// Old spellings that are not the canonical word with `-` for `_`: the model's full name, the
/// lobe search's labels (`convergence.py`'s `phong-fit`), the enum's former variant names.
const DEPRECATED: [(&str, SamplingKind); 5] = [
    ("blinn_phong", SamplingKind::Phong),
    ("phong_fit", SamplingKind::Phong),
    ("two_lobe_fit", SamplingKind::TwoLobe),
    ("anisotropic_blinn_phong", SamplingKind::AnisotropicPhong),
    ("anisotropic", SamplingKind::AnisotropicPhong),
];

impl SamplingKind {
    /// Every kind, in code order.
    pub const ALL: [SamplingKind; 6] = [
        SamplingKind::Uniform,
        SamplingKind::Cosine,
        SamplingKind::Phong,
        SamplingKind::TwoLobe,
        SamplingKind::Tabulated,
        SamplingKind::AnisotropicPhong,
    ];

    /// The canonical name: what files, the CLI and the plugin's `sampling` parameter use.
    pub const fn name(self) -> &'static str {
        match self {
            SamplingKind::Uniform => "uniform",
            SamplingKind::Cosine => "cosine",
            SamplingKind::Phong => "phong",
            SamplingKind::TwoLobe => "two_lobe",
            SamplingKind::Tabulated => "tabulated",
            SamplingKind::AnisotropicPhong => "anisotropic_phong",
        }
    }

    /// The stable number of the C ABI (`NBRDF_SAMPLING_*`).
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The canonical names, comma-separated, for messages.
    pub fn canonical_names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }

    /// Parses a canonical name or a deprecated spelling (case and `-`/`_` aside: `two-lobe`,
    /// `Phong`, or one of the old words such as `blinn_phong` and `phong-fit`).
    pub fn parse_lenient(name: &str) -> Result<ParsedKind, UnknownSamplingKind> {
        if let Ok(kind) = name.parse() {
            return Ok(ParsedKind {
                kind,
                deprecation: None,
            });
        }
        let folded = name.trim().to_ascii_lowercase().replace('-', "_");
        let kind = Self::ALL
            .into_iter()
            .find(|k| k.name() == folded)
            .or_else(|| {
                DEPRECATED
                    .iter()
                    .find(|(old, _)| *old == folded)
                    .map(|p| p.1)
            })
            .ok_or_else(|| UnknownSamplingKind {
                name: name.to_string(),
            })?;
        Ok(ParsedKind {
            kind,
            deprecation: Some(format!(
                "sampling strategy '{name}' is deprecated; use '{}'",
                kind.name()
            )),
        })
    }
}

impl fmt::Display for SamplingKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Canonical names only; [`SamplingKind::parse_lenient`] also takes the old spellings.
impl FromStr for SamplingKind {
    type Err = UnknownSamplingKind;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| UnknownSamplingKind {
                name: name.to_string(),
            })
    }
}

impl From<SamplingKind> for u32 {
    fn from(kind: SamplingKind) -> u32 {
        kind.code()
    }
}

impl TryFrom<u32> for SamplingKind {
    type Error = UnknownSamplingCode;

    fn try_from(code: u32) -> Result<Self, Self::Error> {
        Self::ALL
            .into_iter()
            .find(|k| k.code() == code)
            .ok_or(UnknownSamplingCode(code))
    }
}

impl Serialize for SamplingKind {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

/// Lenient, so that files written with an old spelling keep loading (as their canonical kind).
impl<'de> Deserialize<'de> for SamplingKind {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        SamplingKind::parse_lenient(&name)
            .map(|parsed| parsed.kind)
            .map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_the_c_headers() {
        // The numbers of nbrdf.h's NbrdfSamplingKind, written out independently of the enum.
        let header = [
            ("uniform", 0),
            ("cosine", 1),
            ("phong", 2),
            ("two_lobe", 3),
            ("tabulated", 4),
            ("anisotropic_phong", 5),
        ];
        for (name, code) in header {
            let kind: SamplingKind = name.parse().unwrap();
            assert_eq!(kind.code(), code);
            assert_eq!(SamplingKind::try_from(code), Ok(kind));
            assert_eq!(kind.to_string(), name);
        }
        assert_eq!(SamplingKind::ALL.len(), header.len());
        assert_eq!(SamplingKind::try_from(6), Err(UnknownSamplingCode(6)));
    }

    #[test]
    fn strict_parse_takes_canonical_names_only() {
        for old in ["two-lobe", "blinn_phong", "Phong", " cosine", "ggx", ""] {
            assert_eq!(
                old.parse::<SamplingKind>(),
                Err(UnknownSamplingKind { name: old.into() })
            );
        }
    }

    #[test]
    fn old_spellings_parse_with_a_note() {
        let cases = [
            ("phong", Some(SamplingKind::Phong)),
            ("blinn_phong", Some(SamplingKind::Phong)),
            ("blinn-phong", Some(SamplingKind::Phong)),
            ("phong-fit", Some(SamplingKind::Phong)),
            ("two-lobe", Some(SamplingKind::TwoLobe)),
            ("two-lobe-fit", Some(SamplingKind::TwoLobe)),
            ("anisotropic-phong", Some(SamplingKind::AnisotropicPhong)),
            ("Tabulated", Some(SamplingKind::Tabulated)),
            ("AnisotropicBlinnPhong", None),
            ("ggx", None),
        ];
        for (name, want) in cases {
            let got = SamplingKind::parse_lenient(name);
            assert_eq!(got.as_ref().ok().map(|p| p.kind), want, "{name}");
            if let Ok(ParsedKind { kind, deprecation }) = got {
                match deprecation {
                    None => assert_eq!(name, kind.name()),
                    Some(note) => assert!(
                        name != kind.name() && note.contains(name) && note.contains(kind.name()),
                        "{note}"
                    ),
                }
            }
        }
        let err = SamplingKind::parse_lenient("ggx").unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown sampling strategy 'ggx' (one of uniform, cosine, phong, two_lobe, tabulated, \
             anisotropic_phong)"
        );
    }

    #[test]
    fn serde_writes_canonical_and_reads_old_spellings() {
        assert_eq!(
            serde_json::to_string(&SamplingKind::TwoLobe).unwrap(),
            "\"two_lobe\""
        );
        let old: SamplingKind = serde_json::from_str("\"two-lobe\"").unwrap();
        assert_eq!(old, SamplingKind::TwoLobe);
        assert!(serde_json::from_str::<SamplingKind>("\"ggx\"").is_err());
    }
}
