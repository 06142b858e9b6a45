//! Attribute reading: one rule for time samples, typed conversions from `sdf::Value`, and primvars
//! (interpolation metadata and `:indices`).
//!
//! Every attribute is read at [`TimeCode::EARLIEST`], which openusd resolves to the first time sample
//! when the attribute has samples and to its default value otherwise. Attributes with samples are
//! remembered so the importer can say which values it froze (one warning per prim).

use openusd::sdf::{self, Value};
use openusd::usd::TimeCode;

use super::Importer;
use crate::scene::SceneError;

/// The USD name of a value's type, for messages ("Vec3fVec", "Token", …).
pub(super) fn type_of(v: &Value) -> &'static str {
    v.into()
}

/// A scalar as f64 (any numeric type).
pub(super) fn scalar(v: &Value) -> Option<f64> {
    Some(match v {
        Value::Double(x) => *x,
        Value::Float(x) => f64::from(*x),
        Value::Half(x) => f64::from(x.to_f32()),
        Value::Int(x) => f64::from(*x),
        Value::Uint(x) => f64::from(*x),
        Value::Int64(x) => *x as f64,
        Value::Uint64(x) => *x as f64,
        Value::Uchar(x) => f64::from(*x),
        _ => return None,
    })
}

/// A 3-vector (`float3`, `double3`, `half3`, `color3f`, `vector3f`, `point3f`, …).
pub(super) fn vec3(v: &Value) -> Option<[f64; 3]> {
    Some(match v {
        Value::Vec3f(a) => [a.x, a.y, a.z].map(f64::from),
        Value::Vec3d(a) => [a.x, a.y, a.z],
        Value::Vec3h(a) => [a.x, a.y, a.z].map(|h| f64::from(h.to_f32())),
        _ => return None,
    })
}

/// A 2-vector (`float2`, `double2`, `half2`).
pub(super) fn vec2(v: &Value) -> Option<[f64; 2]> {
    Some(match v {
        Value::Vec2f(a) => [a.x, a.y].map(f64::from),
        Value::Vec2d(a) => [a.x, a.y],
        Value::Vec2h(a) => [a.x, a.y].map(|h| f64::from(h.to_f32())),
        _ => return None,
    })
}

/// An array of 3-vectors.
pub(super) fn vec3_array(v: &Value) -> Option<Vec<[f64; 3]>> {
    Some(match v {
        Value::Vec3fVec(a) => a.iter().map(|p| [p.x, p.y, p.z].map(f64::from)).collect(),
        Value::Vec3dVec(a) => a.iter().map(|p| [p.x, p.y, p.z]).collect(),
        Value::Vec3hVec(a) => a.iter().map(|p| [p.x, p.y, p.z].map(|h| f64::from(h.to_f32()))).collect(),
        _ => return None,
    })
}

/// An array of 2-vectors.
pub(super) fn vec2_array(v: &Value) -> Option<Vec<[f64; 2]>> {
    Some(match v {
        Value::Vec2fVec(a) => a.iter().map(|p| [p.x, p.y].map(f64::from)).collect(),
        Value::Vec2dVec(a) => a.iter().map(|p| [p.x, p.y]).collect(),
        Value::Vec2hVec(a) => a.iter().map(|p| [p.x, p.y].map(|h| f64::from(h.to_f32()))).collect(),
        _ => return None,
    })
}

/// An integer array (`int[]`, `int64[]`, `uint[]`, …) widened to i64.
pub(super) fn int_array(v: &Value) -> Option<Vec<i64>> {
    Some(match v {
        Value::IntVec(a) => a.iter().map(|&x| i64::from(x)).collect(),
        Value::Int64Vec(a) => a.clone(),
        Value::UintVec(a) => a.iter().map(|&x| i64::from(x)).collect(),
        Value::Uint64Vec(a) => a.iter().map(|&x| i64::try_from(x).unwrap_or(i64::MAX)).collect(),
        Value::UcharVec(a) => a.iter().map(|&x| i64::from(x)).collect(),
        _ => return None,
    })
}

/// A token or string.
pub(super) fn token(v: &Value) -> Option<String> {
    match v {
        Value::Token(t) => Some(t.as_str().to_owned()),
        Value::String(s) => Some(s.clone()),
        _ => None,
    }
}

/// A boolean (`bool`, or an integer 0/1 as some exporters write).
pub(super) fn boolean(v: &Value) -> Option<bool> {
    match v {
        Value::Bool(b) => Some(*b),
        Value::Int(i) => Some(*i != 0),
        _ => None,
    }
}

/// How a primvar's values map onto a mesh (UsdGeom interpolation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Interp {
    /// One value for the whole mesh.
    Constant,
    /// One value per face.
    Uniform,
    /// One value per point (`vertex`, and `varying`, which is the same on a polygon cage).
    Vertex,
    /// One value per face-vertex (corner).
    FaceVarying,
}

/// A primvar as authored: values, optional `:indices`, interpolation.
#[derive(Debug, Clone)]
pub(super) struct Primvar<const N: usize> {
    /// Authored values.
    pub values: Vec<[f64; N]>,
    /// `<name>:indices`, when authored: the element values are `values[indices[i]]`.
    pub indices: Option<Vec<i64>>,
    /// Interpolation (metadata).
    pub interp: Interp,
}

/// A conversion from a raw value to `T` (`None`: the value has another type).
pub(super) type Conv<T> = fn(&Value) -> Option<T>;

impl Importer<'_> {
    /// The value of attribute `name` on `prim` (first time sample, else default; `None` when
    /// unauthored or blocked).
    pub(super) fn value(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<Value>, SceneError> {
        let path = prim.append_property(name).map_err(|e| self.usd_err(prim, name, e))?;
        let attr = self.stage.attribute(path);
        let samples = attr.num_time_samples().map_err(|e| self.usd_err(prim, name, e))?;
        let value = attr.get_at::<Value>(TimeCode::EARLIEST).map_err(|e| self.usd_err(prim, name, e))?;
        if samples > 0 && value.is_some() {
            self.note_time_samples(prim, name, samples);
        }
        Ok(value)
    }

    /// The value of `name` converted by `conv`; an authored value of another type is an error naming
    /// the prim, the attribute and the expected type.
    pub(super) fn typed<T>(
        &mut self,
        prim: &sdf::Path,
        name: &str,
        conv: Conv<T>,
        expected: &str,
    ) -> Result<Option<T>, SceneError> {
        match self.value(prim, name)? {
            None => Ok(None),
            Some(v) => conv(&v).map(Some).ok_or_else(|| {
                self.err(
                    prim,
                    format!("attribute `{name}` holds a {} value, expected {expected}", type_of(&v)),
                    format!("author `{name}` as {expected}"),
                )
            }),
        }
    }

    /// A scalar attribute.
    pub(super) fn f64_attr(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<f64>, SceneError> {
        self.typed(prim, name, scalar, "a number (float or double)")
    }

    /// A 3-vector attribute.
    pub(super) fn vec3_attr(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<[f64; 3]>, SceneError> {
        self.typed(prim, name, vec3, "a 3-vector (e.g. color3f, vector3f, float3)")
    }

    /// A 2-vector attribute.
    pub(super) fn vec2_attr(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<[f64; 2]>, SceneError> {
        self.typed(prim, name, vec2, "a 2-vector (e.g. float2)")
    }

    /// A token or string attribute.
    pub(super) fn token_attr(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<String>, SceneError> {
        self.typed(prim, name, token, "a token")
    }

    /// A boolean attribute.
    pub(super) fn bool_attr(&mut self, prim: &sdf::Path, name: &str) -> Result<Option<bool>, SceneError> {
        self.typed(prim, name, boolean, "a bool")
    }

    /// The first authored of several attribute names (e.g. `inputs:intensity`, then the pre-2021 UsdLux
    /// `intensity`).
    pub(super) fn first_of<T>(
        &mut self,
        prim: &sdf::Path,
        names: &[&str],
        conv: Conv<T>,
        expected: &str,
    ) -> Result<Option<T>, SceneError> {
        for name in names {
            if let Some(v) = self.typed(prim, name, conv, expected)? {
                return Ok(Some(v));
            }
        }
        Ok(None)
    }

    /// Reads primvar `name` (values, `:indices`, interpolation). `default_interp` applies when the
    /// `interpolation` metadata is unauthored (`constant` for primvars, `vertex` for `normals`).
    /// Returns `None` (after a warning) for a primvar voltab cannot use.
    pub(super) fn primvar<const N: usize>(
        &mut self,
        prim: &sdf::Path,
        name: &str,
        conv: Conv<Vec<[f64; N]>>,
        default_interp: Interp,
    ) -> Result<Option<Primvar<N>>, SceneError> {
        let expected = if N == 2 { "an array of 2-vectors (e.g. texCoord2f[])" } else { "an array of 3-vectors" };
        let Some(values) = self.typed(prim, name, conv, expected)? else {
            return Ok(None);
        };
        let indices = self.typed(prim, &format!("{name}:indices"), int_array, "an int array")?;
        let attr = prim.append_property(name).map_err(|e| self.usd_err(prim, name, e))?;
        let meta = self.stage.attribute(attr.clone()).get_metadata::<Value>("interpolation");
        let interp = match meta.map_err(|e| self.usd_err(prim, name, e))?.as_ref().and_then(token).as_deref() {
            None => default_interp,
            Some("constant") => Interp::Constant,
            Some("uniform") => Interp::Uniform,
            Some("vertex" | "varying") => Interp::Vertex,
            Some("faceVarying") => Interp::FaceVarying,
            Some(other) => {
                self.warn(
                    prim.as_str(),
                    format!("`{name}` has unknown interpolation \"{other}\"; the primvar is ignored"),
                    "use constant, uniform, vertex, varying or faceVarying",
                );
                return Ok(None);
            }
        };
        let element_size = self.stage.attribute(attr).get_metadata::<Value>("elementSize");
        if let Some(size) = element_size.map_err(|e| self.usd_err(prim, name, e))?.as_ref().and_then(scalar)
            && size != 1.0
        {
            self.warn(
                prim.as_str(),
                format!("`{name}` has elementSize {size}; only 1 is supported, the primvar is ignored"),
                "author one value per element",
            );
            return Ok(None);
        }
        Ok(Some(Primvar { values, indices, interp }))
    }
}
