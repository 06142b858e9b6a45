//! File bytes → validated glTF JSON and buffer bytes.
//!
//! **Input → output.** A `.gltf` (JSON with external `.bin` files or base64 data URIs) or a `.glb`
//! (12-byte header, JSON chunk, optional BIN chunk) → a [`Loaded`] document whose every index
//! reference resolves and whose buffers are read into memory. Images are never read or decoded
//! (voltab uses material factors only).
//!
//! **Why not `gltf::import`.** It decodes every image, rejects `KHR_materials_volume` listed in
//! `extensionsRequired` (the crate's validator only knows the extensions it has built-in readers
//! for) and its URI decoder unwraps invalid percent-encodings. Here the JSON is deserialized
//! straight into `gltf::json::Root` (so serde reports line and column of malformed input), the
//! required extensions are checked against what voltab understands and moved to `extensionsUsed`,
//! and then the crate's validator runs on the rest. Since the JSON never goes back through
//! `gltf::Gltf::from_slice`, a `.glb` needs no rebuilding: its chunks are split here.

use std::path::Path;

use gltf::json;
use gltf::json::validation::{Checked, Validate};

use crate::scene::SceneError;

/// Extensions voltab reads (or, for `KHR_texture_transform`, may safely ignore because textures are
/// not used); anything else in `extensionsRequired` is an error.
pub(super) const UNDERSTOOD_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_volume",
    "KHR_materials_volume_scatter",
    "KHR_texture_transform",
    super::vendor::EXTENSION,
];

/// A parsed, validated document with its buffers.
pub(super) struct Loaded {
    /// The document (every index in range, every enum value known).
    pub doc: gltf::Document,
    /// Bytes of each buffer, at least `byteLength` long.
    pub buffers: Vec<Vec<u8>>,
}

/// Reads and validates `path` (a regular file of at most
/// [`crate::cache::bounded::max_input_bytes`] bytes; its buffer files are resolved in its folder).
pub(super) fn load(path: &Path) -> Result<Loaded, SceneError> {
    let bytes = crate::cache::bounded::read_regular(path, crate::cache::bounded::max_input_bytes()).map_err(|e| {
        let help = match e.kind() {
            std::io::ErrorKind::InvalidInput => "name a regular .gltf or .glb file",
            _ => "check the path and its permissions",
        };
        SceneError::file(path, format!("cannot read the file: {e}"), help)
    })?;
    let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    load_bytes(path, &bytes, Some(&base))
}

/// Parses and validates a document held in memory; `path` names it in messages. External buffer
/// files are read from `base` (refused when `base` is `None`, e.g. when fuzzing).
pub(super) fn load_bytes(path: &Path, bytes: &[u8], base: Option<&Path>) -> Result<Loaded, SceneError> {
    let (json_bytes, bin, glb) = if bytes.starts_with(b"glTF") {
        let chunks = split_glb(path, bytes)?;
        (chunks.json, chunks.bin, true)
    } else {
        (bytes.strip_prefix(b"\xEF\xBB\xBF".as_slice()).unwrap_or(bytes), None, false)
    };
    let mut root: json::Root = serde_json::from_slice(json_bytes).map_err(|e| json_error(path, &e, glb))?;
    check_version(path, &root)?;
    accept_required_extensions(path, &mut root)?;
    check_position_indices(path, &root)?;
    validate(path, &root)?;
    check_layout(path, &root)?;
    let buffers = load_buffers(path, &root, base, bin)?;
    Ok(Loaded { doc: gltf::Document::from_json_without_validation(root), buffers })
}

/// The chunks of a `.glb`.
struct GlbChunks<'a> {
    json: &'a [u8],
    bin: Option<&'a [u8]>,
}

const GLB_JSON: u32 = 0x4E4F_534A;
const GLB_BIN: u32 = 0x004E_4942;

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Splits a binary glTF container: header (magic, version 2, total length), then chunks of
/// (length, type, data); the first chunk is JSON, an optional second one BIN, others are ignored
/// (glTF 2.0 §4.4).
fn split_glb<'a>(path: &Path, bytes: &'a [u8]) -> Result<GlbChunks<'a>, SceneError> {
    let bad = |message: String| {
        SceneError::at(path, "GLB container", message, "re-export the file; it is not a valid binary glTF 2.0 file")
    };
    let (Some(version), Some(length)) = (le_u32(bytes, 4), le_u32(bytes, 8)) else {
        return Err(bad(format!("truncated header: {} bytes, a GLB header has 12", bytes.len())));
    };
    if version != 2 {
        return Err(bad(format!("GLB version {version}; voltab reads glTF 2.0 (GLB version 2)")));
    }
    let length = length as usize;
    if length != bytes.len() {
        return Err(bad(format!("the header gives a length of {length} bytes but the file has {}", bytes.len())));
    }
    let mut at = 12;
    let mut chunks = Vec::new();
    while at < length {
        let (Some(len), Some(kind)) = (le_u32(bytes, at), le_u32(bytes, at + 4)) else {
            return Err(bad(format!("truncated header of chunk {} at byte {at}", chunks.len())));
        };
        let start = at + 8;
        let Some(data) = start.checked_add(len as usize).and_then(|end| bytes.get(start..end)) else {
            return Err(bad(format!(
                "chunk {} at byte {at} claims {len} bytes but only {} remain",
                chunks.len(),
                length - start.min(length)
            )));
        };
        chunks.push((kind, data));
        at = start + data.len();
    }
    match chunks.first() {
        Some(&(GLB_JSON, json)) => {
            let bin = chunks.get(1).and_then(|&(kind, data)| (kind == GLB_BIN).then_some(data));
            Ok(GlbChunks { json, bin })
        }
        Some(&(kind, _)) => Err(bad(format!("the first chunk has type 0x{kind:08X}, expected JSON (0x4E4F534A)"))),
        None => Err(bad("no JSON chunk".into())),
    }
}

/// Malformed JSON (syntax) or JSON that does not have glTF's shape (data), with line and column.
fn json_error(path: &Path, e: &serde_json::Error, glb: bool) -> SceneError {
    let (line, column) = (e.line(), e.column());
    let text = e.to_string();
    let suffix = format!(" at line {line} column {column}");
    let detail = text.strip_suffix(&suffix).unwrap_or(&text);
    let chunk = if glb { "GLB JSON chunk, " } else { "" };
    let (message, help) = match e.classify() {
        serde_json::error::Category::Data => (
            format!("not a valid glTF 2.0 document: {detail}"),
            "the JSON parses but a glTF property has the wrong type or is missing (glTF 2.0 spec §5)",
        ),
        _ => (format!("malformed JSON: {detail}"), "fix the JSON syntax at this position"),
    };
    SceneError::at(path, format!("{chunk}line {line}, column {column}"), message, help)
}

/// `asset.version` must be "2.<minor>" (and `asset.minVersion`, when given, at most 2.0): a glTF
/// 3.0 document may change meanings voltab would silently misread (glTF 2.0 §3.2).
fn check_version(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    let two_x = |v: &str| v.strip_prefix("2.").is_some_and(|m| !m.is_empty() && m.bytes().all(|c| c.is_ascii_digit()));
    if !two_x(&root.asset.version) {
        return Err(SceneError::at(
            path,
            "asset.version",
            format!("glTF version \"{}\" is not supported", shorten(&root.asset.version)),
            "voltab reads glTF 2.x; the version must be \"2.0\" (or another 2.minor)",
        ));
    }
    if let Some(min) = root.asset.min_version.as_deref()
        && min != "2.0"
    {
        return Err(SceneError::at(
            path,
            "asset.minVersion",
            format!("the file needs a glTF reader of version {} or newer", shorten(min)),
            "voltab reads glTF 2.0; re-export the asset for glTF 2.0",
        ));
    }
    Ok(())
}

/// Layout rules the crate's validator does not check (glTF 2.0 §3.6.2.4): every bufferView lies
/// inside its buffer's declared `byteLength`, and every accessor's start in the buffer
/// (`bufferView.byteOffset + accessor.byteOffset`) and its view's stride are multiples of its
/// component size.
fn check_layout(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    for (i, v) in root.buffer_views.iter().enumerate() {
        let Some(buffer) = root.buffers.get(v.buffer.value()) else { continue };
        let offset = v.byte_offset.map_or(0, |o| o.0);
        let end = offset.checked_add(v.byte_length.0);
        if end.is_none_or(|e| e > buffer.byte_length.0) {
            return Err(SceneError::at(
                path,
                format!("bufferViews[{i}]"),
                format!(
                    "byteOffset {offset} + byteLength {} lies outside buffers[{}] (byteLength {})",
                    v.byte_length.0,
                    v.buffer.value(),
                    buffer.byte_length.0
                ),
                "the file is corrupt or was written by a broken exporter",
            ));
        }
    }
    for (i, a) in root.accessors.iter().enumerate() {
        let (Some(view), Checked::Valid(ct)) = (a.buffer_view, &a.component_type) else { continue };
        let Some(v) = root.buffer_views.get(view.value()) else { continue };
        let size = ct.0.size() as u64;
        let start = v.byte_offset.map_or(0, |o| o.0).saturating_add(a.byte_offset.map_or(0, |o| o.0));
        if !start.is_multiple_of(size) {
            return Err(SceneError::at(
                path,
                format!("accessors[{i}]"),
                format!(
                    "starts at byte {start} of its buffer (bufferViews[{}].byteOffset + byteOffset), not a multiple \
                     of its {size}-byte component",
                    view.value()
                ),
                "glTF 2.0 requires accessor data aligned to the component size; re-export the asset",
            ));
        }
        if let Some(stride) = v.byte_stride
            && !(stride.0 as u64).is_multiple_of(size)
        {
            return Err(SceneError::at(
                path,
                format!("bufferViews[{}].byteStride", view.value()),
                format!("byteStride {} is not a multiple of the {size}-byte component of accessors[{i}]", stride.0),
                "glTF 2.0 requires strides aligned to the component size; re-export the asset",
            ));
        }
    }
    Ok(())
}

/// Rejects required extensions voltab does not understand; moves the rest to `extensionsUsed` so
/// the gltf crate's validator (which only accepts its built-in readers) does not reject them.
fn accept_required_extensions(path: &Path, root: &mut json::Root) -> Result<(), SceneError> {
    if let Some(ext) = root.extensions_required.iter().find(|e| !UNDERSTOOD_EXTENSIONS.contains(&e.as_str())) {
        return Err(SceneError::at(
            path,
            "extensionsRequired",
            format!("the file requires extension \"{ext}\", which voltab does not support"),
            format!("voltab understands {}; re-export the asset without \"{ext}\"", UNDERSTOOD_EXTENSIONS.join(", ")),
        ));
    }
    for ext in std::mem::take(&mut root.extensions_required) {
        if !root.extensions_used.contains(&ext) {
            root.extensions_used.push(ext);
        }
    }
    Ok(())
}

/// The crate's validator indexes `accessors[POSITION]` without a bounds check (it reads the
/// accessor's min/max); check those indices first so a broken file gives an error, not a panic.
fn check_position_indices(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(index) = prim.attributes.get(&Checked::Valid(json::mesh::Semantic::Positions))
                && index.value() >= root.accessors.len()
            {
                return Err(SceneError::at(
                    path,
                    format!("meshes[{m}].primitives[{p}].attributes[\"POSITION\"]"),
                    format!(
                        "accessor index {} is out of range (the file has {} accessors)",
                        index.value(),
                        root.accessors.len()
                    ),
                    "the file is corrupt or was written by a broken exporter",
                ));
            }
        }
    }
    Ok(())
}

/// Runs the gltf crate's validator (index ranges, enum values, required properties). POSITION
/// `min`/`max`, which the spec requires but voltab never reads, are not enforced.
fn validate(path: &Path, root: &json::Root) -> Result<(), SceneError> {
    let mut problems = Vec::new();
    root.validate(root, json::Path::new, &mut |p, e| problems.push((p().as_str().to_owned(), e)));
    problems.retain(|(p, _)| !(p.contains("attributes[\"POSITION\"]") && (p.ends_with(".min") || p.ends_with(".max"))));
    let Some((first, error)) = problems.first() else { return Ok(()) };
    let more = match problems.len() {
        1 => String::new(),
        n => format!(
            " (and {} more: {})",
            n - 1,
            problems[1..].iter().take(4).map(|(p, e)| format!("{p}: {e}")).collect::<Vec<_>>().join("; ")
        ),
    };
    Err(SceneError::at(
        path,
        first.clone(),
        format!("invalid glTF: {error}{more}"),
        "the file breaks the glTF 2.0 schema (an index out of range, an unknown enum value or a missing property)",
    ))
}

/// Reads every buffer: the GLB BIN chunk, a data URI or a file next to the document.
fn load_buffers(
    path: &Path,
    root: &json::Root,
    base: Option<&Path>,
    mut bin: Option<&[u8]>,
) -> Result<Vec<Vec<u8>>, SceneError> {
    let mut out = Vec::with_capacity(root.buffers.len());
    for (i, buffer) in root.buffers.iter().enumerate() {
        let loc = match buffer.name.as_deref() {
            Some(name) => format!("buffers[{i}] \"{name}\""),
            None => format!("buffers[{i}]"),
        };
        let data = match buffer.uri.as_deref() {
            None => bin.take().map(<[u8]>::to_vec).ok_or_else(|| {
                SceneError::at(
                    path,
                    &loc,
                    "the buffer has no uri and there is no unused GLB BIN chunk to take its bytes from",
                    "only the first buffer of a .glb may omit its uri; give the others a file name or data URI",
                )
            })?,
            Some(uri) => read_uri(base, uri, buffer.byte_length.0)
                .map_err(|(message, help)| SceneError::at(path, &loc, message, help))?,
        };
        let want = buffer.byte_length.0;
        if (data.len() as u64) < want {
            return Err(SceneError::at(
                path,
                &loc,
                format!("the buffer has {} bytes but its byteLength is {want}", data.len()),
                "the buffer file is truncated or belongs to another version of the asset",
            ));
        }
        // Bytes past byteLength (GLB padding) are not part of the buffer: views are checked against
        // what remains.
        let mut data = data;
        data.truncate(usize::try_from(want).unwrap_or(usize::MAX));
        out.push(data);
    }
    Ok(out)
}

/// Resolves a buffer URI (RFC 3986 relative reference, `file:` or `data:`) to its bytes. A file
/// must be a relative path that stays inside the document's folder (no absolute path, no `..`
/// climbing out), a regular file, and exactly `byte_length` bytes long (up to 3 bytes of padding
/// allowed); only `byte_length` bytes are read.
fn read_uri(base: Option<&Path>, uri: &str, byte_length: u64) -> Result<Vec<u8>, (String, String)> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((header, payload)) = rest.split_once(',') else {
            return Err((format!("malformed data URI (no ','): \"{}\"", shorten(uri)), "see RFC 2397".into()));
        };
        return if header.ends_with(";base64") {
            decode_base64(payload).map_err(|e| (format!("data URI: {e}"), "the base64 payload is corrupt".into()))
        } else {
            percent_decode(payload).map_err(|e| (format!("data URI: {e}"), "see RFC 2397".into()))
        };
    }
    let scheme = uri.split_once(':').map(|(s, _)| s).filter(|s| {
        s.len() > 1 && !s.contains('/') && s.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
    });
    let file = match scheme {
        Some("file") => {
            let rest = &uri[5..];
            percent_decode(rest.strip_prefix("//").unwrap_or(rest))
        }
        Some(other) => {
            return Err((
                format!("URI scheme \"{other}:\" is not supported: \"{}\"", shorten(uri)),
                "voltab reads buffers from files next to the document or from data URIs; download the buffer first"
                    .into(),
            ));
        }
        None => percent_decode(uri),
    };
    let file = file.map_err(|e| (format!("uri \"{}\": {e}", shorten(uri)), "fix the percent-encoding".into()))?;
    let file = String::from_utf8(file).map_err(|_| {
        (format!("uri \"{}\" does not decode to UTF-8", shorten(uri)), "fix the percent-encoding".into())
    })?;
    let inside = "buffer files must be relative paths inside the document's folder (glTF URIs are relative references)";
    let rel = Path::new(&file);
    if rel.has_root() || rel.components().any(|c| matches!(c, std::path::Component::Prefix(_))) {
        return Err((format!("buffer uri \"{}\" is an absolute path", shorten(&file)), inside.into()));
    }
    let mut depth = 0i64;
    for c in rel.components() {
        match c {
            std::path::Component::ParentDir => depth -= 1,
            std::path::Component::Normal(_) => depth += 1,
            _ => {}
        }
        if depth < 0 {
            return Err((
                format!("buffer uri \"{}\" leads out of the document's folder", shorten(&file)),
                inside.into(),
            ));
        }
    }
    let Some(base) = base else {
        return Err((
            format!("buffer uri \"{}\" names a file, but this document was read from memory", shorten(&file)),
            "embed the buffer (GLB BIN chunk or data URI)".into(),
        ));
    };
    let full = base.join(rel);
    let cannot = |e: std::io::Error| {
        (
            format!("cannot read buffer file \"{file}\" ({}): {e}", full.display()),
            "the .bin file must sit next to the .gltf (URIs are relative to the document's folder)".into(),
        )
    };
    let size = crate::cache::bounded::check_regular(&full, u64::MAX).map_err(cannot)?;
    if size > byte_length.saturating_add(3) {
        return Err((
            format!("buffer file \"{file}\" has {size} bytes but the buffer's byteLength is {byte_length}"),
            "the byteLength must give the file's size; the file belongs to another version of the asset".into(),
        ));
    }
    if size < byte_length {
        return Err((
            format!("the buffer has {size} bytes but its byteLength is {byte_length}"),
            "the buffer file is truncated or belongs to another version of the asset".into(),
        ));
    }
    crate::cache::bounded::read_regular_range(&full, 0, Some(byte_length), byte_length).map_err(cannot)
}

fn shorten(s: &str) -> String {
    if s.len() <= 80 {
        return s.to_owned();
    }
    let cut = (0..=72).rev().find(|&i| s.is_char_boundary(i)).unwrap_or(0);
    format!("{}…", &s[..cut])
}

/// `%XX` escapes → bytes.
fn percent_decode(s: &str) -> Result<Vec<u8>, String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = |b: Option<&u8>| b.and_then(|b| (*b as char).to_digit(16));
            match (hex(bytes.get(i + 1)), hex(bytes.get(i + 2))) {
                (Some(h), Some(l)) => out.push((h * 16 + l) as u8),
                _ => return Err(format!("invalid percent-escape at character {i}")),
            }
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    Ok(out)
}

/// Standard base64 (RFC 4648 §4) with optional padding; whitespace is skipped.
fn decode_base64(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    let mut padding = false;
    for (i, c) in s.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => {
                padding = true;
                continue;
            }
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return Err(format!("invalid base64 character {:?} at {i}", c as char)),
        };
        if padding {
            return Err(format!("base64 data after '=' padding at {i}"));
        }
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
