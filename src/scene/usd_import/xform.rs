//! Stage units and axes, and prim transforms.
//!
//! openusd has no local-to-world helper, so the importer composes `local_to_parent_transform` down
//! the hierarchy during its depth-first traversal (parents are visited before children), honouring
//! `!resetXformStack!`. openusd's matrices are row-major for row vectors (`p' = p·M`, translation in
//! the last row); read column-major by glam they are the usual column-vector matrices, so the
//! world matrix of a prim is `W = W_parent · L` and the voltab world is `frame · W`.

use glam::{DMat3, DMat4, DVec3, DVec4};
use openusd::schemas::geom::{Imageable, Xformable};
use openusd::sdf::Value;
use openusd::usd::{Prim, SchemaBase, SchemaKind, TimeCode};

use super::Importer;
use super::values::scalar;
use crate::scene::SceneError;

/// USD's fallback `metersPerUnit` (centimetres).
pub(super) const FALLBACK_METERS_PER_UNIT: f64 = 0.01;

/// How stage coordinates map to voltab's world (+Y up, metres).
#[derive(Debug, Clone)]
pub(super) struct Frame {
    /// `metersPerUnit`.
    pub mpu: f64,
    /// The stage's up axis in stage coordinates.
    pub up: DVec3,
    /// Stage → world: scale by `metersPerUnit`, then (Z-up stages) rotate −90° about X.
    pub matrix: DMat4,
}

impl Frame {
    /// The frame for a stage's `metersPerUnit` and whether it is Z-up.
    pub(super) fn new(mpu: f64, z_up: bool) -> Frame {
        let scale = DMat4::from_scale(DVec3::splat(mpu));
        // Rx(−90°), spelled exactly: stage +Z (up) → world +Y, stage +Y → world −Z.
        let rotate = if z_up { DMat4::from_cols(DVec4::X, DVec4::NEG_Z, DVec4::Y, DVec4::W) } else { DMat4::IDENTITY };
        let up = if z_up { DVec3::Z } else { DVec3::Y };
        Frame { mpu, up, matrix: rotate * scale }
    }
}

/// Any prim seen through the `Xformable` schema (openusd only implements it on typed views).
struct AnyXformable(Prim);

impl SchemaBase for AnyXformable {
    const KIND: SchemaKind = SchemaKind::AbstractTyped;

    fn prim(&self) -> &Prim {
        &self.0
    }
}

impl Imageable for AnyXformable {}
impl Xformable for AnyXformable {}

/// xformOp kinds openusd composes (anything else is identity in openusd, so voltab warns).
const KNOWN_OPS: [&str; 18] = [
    "translate",
    "translateX",
    "translateY",
    "translateZ",
    "scale",
    "scaleX",
    "scaleY",
    "scaleZ",
    "rotateX",
    "rotateY",
    "rotateZ",
    "rotateXYZ",
    "rotateXZY",
    "rotateYXZ",
    "rotateYZX",
    "rotateZXY",
    "rotateZYX",
    "orient",
];

impl Importer<'_> {
    /// Reads `metersPerUnit` and `upAxis` into a [`Frame`], warning when `metersPerUnit` is unauthored.
    pub(super) fn read_frame(&mut self) -> Result<Frame, SceneError> {
        let layer = self.file.display().to_string();
        let meta = |imp: &Self, key: &str| {
            imp.stage.stage_metadata(key).map_err(|e| {
                SceneError::at(
                    imp.file,
                    format!("layer metadata `{key}`"),
                    format!("cannot read it: {e:#}"),
                    "re-export the layer",
                )
            })
        };
        let mpu = match meta(self, "metersPerUnit")? {
            None => {
                self.warn(
                    &layer,
                    format!(
                        "the layer does not author metersPerUnit; using USD's fallback {FALLBACK_METERS_PER_UNIT} \
                         (centimetres)"
                    ),
                    "author `metersPerUnit = 1` (metres) or the stage's real unit in the layer metadata",
                );
                FALLBACK_METERS_PER_UNIT
            }
            Some(v) => match scalar(&v) {
                Some(m) if m.is_finite() && m > 0.0 => m,
                _ => {
                    return Err(SceneError::at(
                        self.file,
                        "layer metadata `metersPerUnit`",
                        format!("metersPerUnit = {v:?} is not a positive number"),
                        "author a positive `metersPerUnit`, e.g. 1 for metres or 0.01 for centimetres",
                    ));
                }
            },
        };
        let z_up = match meta(self, "upAxis")? {
            None => false,
            Some(Value::Token(t)) if t.as_str() == "Y" => false,
            Some(Value::Token(t)) if t.as_str() == "Z" => true,
            Some(v) => {
                self.warn(
                    &layer,
                    format!("upAxis = {v:?} is neither \"Y\" nor \"Z\"; reading the stage as Y-up"),
                    "author `upAxis = \"Y\"` or `upAxis = \"Z\"`",
                );
                false
            }
        };
        Ok(Frame::new(mpu, z_up))
    }

    /// The prim's local-to-parent matrix (column-vector convention) and whether it resets the
    /// transform stack. Unknown or valueless ops and time-sampled ops give warnings.
    pub(super) fn local_transform(&mut self, prim: &Prim) -> Result<(DMat4, bool), SceneError> {
        let path = prim.path().clone();
        let x = AnyXformable(prim.clone());
        let order = x.xform_op_order().map_err(|e| self.usd_err(&path, "xformOpOrder", e))?;
        let Some(order) = order else {
            return Ok((DMat4::IDENTITY, false));
        };
        for (i, op) in order.iter().enumerate() {
            if op == "!resetXformStack!" {
                if i > 0 {
                    return Err(self.err(
                        &path,
                        format!("xformOpOrder lists !resetXformStack! at position {i}"),
                        "!resetXformStack! is only valid as the first entry of xformOpOrder",
                    ));
                }
                continue;
            }
            let name = op.strip_prefix("!invert!").unwrap_or(op);
            if !super::locate::is_attribute_name(name) {
                return Err(self.err(
                    &path,
                    format!("xformOpOrder entry {op:?} is not an attribute name"),
                    "list xformOp attribute names such as \"xformOp:translate\" (identifiers joined by ':')",
                ));
            }
            let kind = name.strip_prefix("xformOp:").and_then(|k| k.split(':').next()).unwrap_or("");
            if !KNOWN_OPS.contains(&kind) && kind != "transform" {
                self.warn(
                    path.as_str(),
                    format!("xformOp `{name}` has an unsupported kind; it is read as identity"),
                    "use translate, scale, rotateX/Y/Z, rotateXYZ (any order), orient or transform",
                );
                continue;
            }
            // Reading the op here records time samples; the value itself is composed by openusd below.
            if self.value(&path, name)?.is_none() {
                self.warn(
                    path.as_str(),
                    format!("xformOpOrder lists `{name}` but it has no value; it is read as identity"),
                    "author the op's value or remove it from xformOpOrder",
                );
            }
        }
        let m = x.local_to_parent_transform(TimeCode::EARLIEST).map_err(|e| {
            self.err(&path, format!("cannot compose the transform: {e:#}"), "fix the xformOps listed in xformOpOrder")
        })?;
        let resets = order.first().is_some_and(|op| op == "!resetXformStack!");
        Ok((DMat4::from_cols_array(&m.0), resets))
    }
}

/// The matrix that maps local normals (and plane normals) to world: the inverse transpose of the
/// linear part, `None` when the transform is singular.
pub(super) fn normal_matrix(m: &DMat4) -> Option<DMat3> {
    let l = DMat3::from_mat4(*m);
    let det = l.determinant();
    (det.is_finite() && det.abs() > 1e-300).then(|| l.inverse().transpose())
}
