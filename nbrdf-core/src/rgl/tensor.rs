//! Mitsuba's tensor file format (`TensorFile`, `src/core/tensor.cpp`), the container of the RGL
//! material database's `.bsdf` measurements.
//!
//! Layout (little endian): the 12 bytes `"tensor_file\0"`, a version `(major, minor)` of two
//! `u8` (Mitsuba accepts minor 0), a `u32` field count, then per field: `u16` name length, the
//! name, `u16` number of dimensions, `u8` dtype (Mitsuba's `Struct::Type` as written by the RGL
//! tools: 1 = uint8 ... 10 = float32, 11 = float64), `u64` byte offset of the data from the start
//! of the file, and one `u64` per dimension (row-major, last dimension contiguous).
//!
//! Everything a header claims is checked against the file's length before any buffer is sized
//! from it, so a malformed or hostile file gives an error naming the file and the field, never a
//! panic or a huge allocation.

use crate::error::{NbrdfError, Result};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 12] = b"tensor_file\0";
/// Magic, version and field count.
const PREAMBLE: usize = 12 + 2 + 4;
/// The smallest field header: name length, empty name, ndim, dtype, offset.
const MIN_FIELD_HEADER: usize = 2 + 2 + 1 + 8;

/// Element type of a field, numbered as the files store it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DType {
    UInt8,
    Int8,
    UInt16,
    Int16,
    UInt32,
    Int32,
    UInt64,
    Int64,
    Float16,
    Float32,
    Float64,
}

impl DType {
    fn from_code(code: u8) -> Option<DType> {
        use DType::*;
        Some(match code {
            1 => UInt8,
            2 => Int8,
            3 => UInt16,
            4 => Int16,
            5 => UInt32,
            6 => Int32,
            7 => UInt64,
            8 => Int64,
            9 => Float16,
            10 => Float32,
            11 => Float64,
            _ => return None,
        })
    }

    /// The code a file stores for this type.
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    pub fn size(self) -> usize {
        use DType::*;
        match self {
            UInt8 | Int8 => 1,
            UInt16 | Int16 | Float16 => 2,
            UInt32 | Int32 | Float32 => 4,
            UInt64 | Int64 | Float64 => 8,
        }
    }
}

impl fmt::Display for DType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = format!("{self:?}").to_lowercase();
        f.write_str(&name)
    }
}

/// One named array of a tensor file (its bytes stay in the file buffer).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Field {
    pub dtype: DType,
    pub shape: Vec<usize>,
    offset: usize,
    /// Number of elements (product of the shape; checked against the file length).
    len: usize,
}

impl Field {
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// A parsed tensor file: its bytes and the index of its fields.
pub struct TensorFile {
    path: PathBuf,
    bytes: Vec<u8>,
    fields: BTreeMap<String, Field>,
    version: (u8, u8),
}

impl TensorFile {
    /// Reads and indexes `path` (the data is read once; fields are views into it).
    pub fn read(path: impl AsRef<Path>) -> Result<TensorFile> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| NbrdfError::io(path, e))?;
        TensorFile::parse(bytes, path)
    }

    /// Indexes `bytes`, the content of the file `path` (named in errors).
    pub fn parse(bytes: Vec<u8>, path: impl Into<PathBuf>) -> Result<TensorFile> {
        let path = path.into();
        match index_fields(&bytes) {
            Ok((version, fields)) => Ok(TensorFile {
                path,
                bytes,
                fields,
                version,
            }),
            Err(message) => Err(NbrdfError::format(&path, format!("tensor file: {message}"))),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn version(&self) -> (u8, u8) {
        self.version
    }

    pub fn has_field(&self, name: &str) -> bool {
        self.fields.contains_key(name)
    }

    pub fn field_names(&self) -> impl Iterator<Item = &str> {
        self.fields.keys().map(String::as_str)
    }

    /// The field `name`, or an error naming the file and the field.
    pub fn field(&self, name: &str) -> Result<&Field> {
        self.fields
            .get(name)
            .ok_or_else(|| self.error(name, "missing".into()))
    }

    /// The float32 field `name` with `ndim` dimensions: its shape and values, all finite.
    pub fn f32_array(&self, name: &str, ndim: usize) -> Result<(Vec<usize>, Vec<f32>)> {
        let field = self.typed_field(name, DType::Float32, ndim)?;
        let values: Vec<f32> = self
            .field_bytes(field)
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.error(
                name,
                format!("element {i} is {} (values must be finite)", values[i]),
            ));
        }
        Ok((field.shape.clone(), values))
    }

    /// The uint8 field `name` with `ndim` dimensions: its shape and bytes.
    pub fn u8_array(&self, name: &str, ndim: usize) -> Result<(Vec<usize>, Vec<u8>)> {
        let field = self.typed_field(name, DType::UInt8, ndim)?;
        Ok((field.shape.clone(), self.field_bytes(field).to_vec()))
    }

    /// An error about field `name` of this file.
    pub fn error(&self, name: &str, message: String) -> NbrdfError {
        NbrdfError::format(&self.path, format!("field \"{name}\": {message}"))
    }

    fn typed_field(&self, name: &str, dtype: DType, ndim: usize) -> Result<&Field> {
        let field = self.field(name)?;
        if field.dtype != dtype {
            return Err(self.error(name, format!("dtype is {}, expected {dtype}", field.dtype)));
        }
        if field.shape.len() != ndim {
            return Err(self.error(
                name,
                format!(
                    "shape {:?} has {} dimensions, expected {ndim}",
                    field.shape,
                    field.shape.len()
                ),
            ));
        }
        Ok(field)
    }

    fn field_bytes(&self, field: &Field) -> &[u8] {
        &self.bytes[field.offset..field.offset + field.len * field.dtype.size()]
    }
}

/// Bounds-checked little-endian reads from a byte buffer.
/// Fields by name.
type FieldIndex = BTreeMap<String, Field>;

/// A step of the parse, or the message saying what is wrong (the caller names the file).
type FormatResult<T> = std::result::Result<T, String>;

/// The version and field index of a tensor file's `bytes`, or the message saying what is wrong
/// (the caller names the file).
fn index_fields(bytes: &[u8]) -> FormatResult<((u8, u8), FieldIndex)> {
    let (version, count) = read_preamble(bytes)?;
    let mut reader = Reader {
        bytes,
        pos: PREAMBLE,
    };
    let mut fields = BTreeMap::new();
    for index in 0..count {
        let (name, field) = read_field_header(&mut reader, index, count)?;
        if fields.insert(name.clone(), field).is_some() {
            return Err(format!("field \"{name}\" appears twice"));
        }
    }
    Ok((version, fields))
}

/// Checks the magic and version and returns them with the field count, which is bounded by
/// what the file can hold so nothing is allocated from an absurd count.
fn read_preamble(bytes: &[u8]) -> FormatResult<((u8, u8), usize)> {
    if bytes.len() < PREAMBLE {
        return Err(format!(
            "{} bytes, too short for a tensor file header (truncated?)",
            bytes.len()
        ));
    }
    if &bytes[..12] != MAGIC {
        return Err("not a tensor file (missing the \"tensor_file\" header)".into());
    }
    let version = (bytes[12], bytes[13]);
    if version.1 != 0 {
        return Err(format!("unsupported version {}.{}", version.0, version.1));
    }
    let count = Reader { bytes, pos: 14 }.u32().unwrap_or(0) as usize;
    // Every field header takes at least MIN_FIELD_HEADER bytes: a count the file cannot hold
    // is rejected before anything is allocated from it.
    if count > (bytes.len() - PREAMBLE) / MIN_FIELD_HEADER {
        return Err(format!(
            "header claims {count} fields, more than the {} byte file can hold",
            bytes.len()
        ));
    }
    Ok((version, count))
}

/// Reads header `index` (of `count`) at the reader's position: the field's name and its
/// description, whose data is checked to lie inside the file.
fn read_field_header(
    reader: &mut Reader<'_>,
    index: usize,
    count: usize,
) -> FormatResult<(String, Field)> {
    let truncated = || format!("field header {index} of {count} is truncated");
    let name_len = reader.u16().ok_or_else(truncated)?;
    let name = reader.take(name_len as usize).ok_or_else(truncated)?;
    let Ok(name) = std::str::from_utf8(name).map(str::to_owned) else {
        return Err(format!("field {index}: name is not UTF-8"));
    };
    let (Some(ndim), Some(code), Some(offset)) = (reader.u16(), reader.u8(), reader.u64()) else {
        return Err(truncated());
    };
    let Some(dtype) = DType::from_code(code) else {
        return Err(format!("field \"{name}\": unknown dtype code {code}"));
    };
    let mut shape = Vec::with_capacity((ndim as usize).min(reader.remaining() / 8));
    for _ in 0..ndim {
        shape.push(reader.u64().ok_or_else(truncated)?);
    }
    let file_len = reader.bytes.len();
    let elements = shape.iter().try_fold(1u64, |acc, &n| acc.checked_mul(n));
    let end = elements
        .and_then(|n| n.checked_mul(dtype.size() as u64))
        .and_then(|size| size.checked_add(offset));
    match end {
        Some(end) if end <= file_len as u64 => {}
        _ => {
            return Err(format!(
                "field \"{name}\" ({dtype}, shape {shape:?}, offset {offset}) extends past the end of the {file_len} byte file (truncated?)"
            ))
        }
    }
    let field = Field {
        dtype,
        // Fits usize: bounded by the file length above.
        shape: shape.iter().map(|&n| n as usize).collect(),
        offset: offset as usize,
        len: elements.unwrap_or(0) as usize,
    };
    Ok((name, field))
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let slice = self.bytes.get(self.pos..end)?;
        self.pos = end;
        Some(slice)
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn u8(&mut self) -> Option<u8> {
        self.take(1).map(|b| b[0])
    }

    fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|b| u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self) -> Option<u32> {
        self.take(4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }

    fn u64(&mut self) -> Option<u64> {
        self.take(8)
            .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
}

/// Writes a tensor file holding `fields` (name, dtype, shape, raw little-endian data), with the
/// data 8-byte aligned as the RGL files are. For tests and for tools that produce measurements.
pub fn write_tensor_file(fields: &[(&str, DType, &[usize], &[u8])]) -> Vec<u8> {
    let mut header = Vec::new();
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&[1, 0]);
    header.extend_from_slice(&(fields.len() as u32).to_le_bytes());
    let header_len = header.len()
        + fields
            .iter()
            .map(|(name, _, shape, _)| MIN_FIELD_HEADER + name.len() + 8 * shape.len())
            .sum::<usize>();
    let align = |n: usize| n.div_ceil(8) * 8;
    let mut offset = align(header_len);
    let mut body = Vec::new();
    for (name, dtype, shape, data) in fields {
        header.extend_from_slice(&(name.len() as u16).to_le_bytes());
        header.extend_from_slice(name.as_bytes());
        header.extend_from_slice(&(shape.len() as u16).to_le_bytes());
        header.push(dtype.code());
        header.extend_from_slice(&(offset as u64).to_le_bytes());
        for &n in shape.iter() {
            header.extend_from_slice(&(n as u64).to_le_bytes());
        }
        body.resize(offset - align(header_len), 0);
        body.extend_from_slice(data);
        offset = align(align(header_len) + body.len());
    }
    header.resize(align(header_len), 0);
    header.extend_from_slice(&body);
    header
}
